#!/bin/bash
# A measurement of docs/contact.md ("The 4-box pile: the cost of an iteration and the
# landing"): the contact entries reserved ahead by vertex proximity. Run from the repository
# root (serial, one BLAS thread):
#   OPENBLAS_NUM_THREADS=1 bash docs/contact_scenes/reserve_proximity.sh SCENE STEPS K
exec .venv/bin/python - "$@" <<'PY'
"""A measurement of docs/contact.md ("The 4-box pile: the cost of an iteration and the
landing"): whenever the Hessian's pattern is widened for new contact pairs
(``Matrices.grow_pattern``, serial), widen it also by every pair of surface vertices of
different bodies closer than R = d-hat + K x the longest surface edge (K the third
argument; a KD-tree on the current positions), so that pairs appearing later find their
entries reserved and MUMPS redoes its analysis less often. Prints the Newton iterations, the symbolic and numeric
factorisations, the stepping CPU and the final nonzeros. Usage (repository root, one BLAS
thread): bash docs/contact_scenes/reserve_proximity.sh SCENE STEPS K (K = 0: no
reservation)."""
import sys, os, time
import numpy as np
from scipy.spatial import cKDTree
from petsc4py import PETSc
import fem_anim.problem.matrices as m
import fem_anim.problem.objective as o
from fem_anim.scene.loading import load_scene
from fem_anim.simulation.loop import Simulation
FACTOR = float(sys.argv[3])
sim = Simulation(load_scene(sys.argv[1], ["output.render=false"]))
p = sim.problem
ipc = p.ipc
mesh = ipc.halo.mesh
edges = mesh.edges
L = np.linalg.norm(mesh.rest_positions[edges[:, 0]] - mesh.rest_positions[edges[:, 1]], axis=1).max()
R = ipc.dhat + FACTOR * L
print("dhat", ipc.dhat, "Lmax", L, "R", R)
orig = m.Matrices.grow_pattern
def grow(self, A, rows, cols):
    if FACTOR > 0 and A.assembled:
        # would it grow? only then add the proximity pairs
        x = ipc._update()
        pairs = cKDTree(x).query_pairs(R, output_type="ndarray")
        g = ipc.gdim
        halo = ipc.halo
        to_global = halo.unknown_global.reshape(-1, g)
        free = halo.free.reshape(-1, g)
        lab = getattr(halo, "labels", None)
        if lab is None:
            lab = halo.vertex_body
        pairs = pairs[lab[pairs[:, 0]] != lab[pairs[:, 1]]]
        a, b = pairs[:, 0], pairs[:, 1]
        ii = np.repeat(np.arange(g), g); jj = np.tile(np.arange(g), g)
        r = to_global[a][:, ii].ravel(); c = to_global[b][:, jj].ravel()
        fr = free[a][:, ii].ravel() & free[b][:, jj].ravel()
        rr = np.r_[rows, r[fr], c[fr]]; cc = np.r_[cols, c[fr], r[fr]]
        n_before = self.pattern_growths
        res = orig(self, A, rows, cols)
        if res:  # grew for real pairs: widen by the proximity pairs as well
            orig(self, A, rr, cc)
            self.pattern_growths = n_before + 1
        return res
    return orig(self, A, rows, cols)
m.Matrices.grow_pattern = grow
ev = {k: PETSc.Log.Event(k) for k in ("MatCholFctrSym", "MatCholFctrNum")}
st = sim.initial_state(); tot = 0; t0 = time.process_time()
for k in range(int(sys.argv[2])):
    st, stats = sim.step(st, 0.01); tot += stats.newton_its
print(f"R factor {FACTOR}: its {tot} sym {ev['MatCholFctrSym'].getPerfInfo()['count']} num {ev['MatCholFctrNum'].getPerfInfo()['count']} cpu {time.process_time()-t0:.1f} nnz {sim.minimiser.A.getInfo()['nz_used']:.0f} growths {p.pattern_growths}")
PY
