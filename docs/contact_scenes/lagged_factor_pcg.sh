#!/bin/bash
# A measurement of docs/contact.md ("The 4-box pile: the cost of an iteration and the
# landing"): CG on each Hessian of one step with the previous Hessian's MUMPS factorisation
# as preconditioner. Run from the repository root (serial, one BLAS thread):
#   OPENBLAS_NUM_THREADS=1 bash docs/contact_scenes/lagged_factor_pcg.sh SCENE STEP
exec .venv/bin/python - "$@" <<'PY'
"""Store every Hessian of step STEP of SCENE (serial), then solve H_k z = b (b random) by CG
preconditioned with the MUMPS Cholesky factorisation of H_{k-1}, to relative residuals 1e-6
and 1e-10, and print per Hessian: whether its pattern is H_{k-1}'s, CG's iterations, its KSP
reason (2: converged; -8/-10: an indefinite preconditioner or matrix) and the solve's
process CPU (the preconditioner's set-up excluded)."""
import sys, time
import numpy as np
from petsc4py import PETSc
import fem_anim.problem.objective as o
from fem_anim.scene.loading import load_scene
from fem_anim.simulation.loop import Simulation
H = []
orig = o.EnergyProblem.jacobian
record = [False]
def j(self, snes, x, A, P):
    orig(self, snes, x, A, P)
    if record[0]:
        H.append(A.copy())
o.EnergyProblem.jacobian = j
sim = Simulation(load_scene(sys.argv[1], ["output.render=false"]))
st = sim.initial_state()
target = int(sys.argv[2])
for k in range(target):
    record[0] = (k == target - 1)
    st, stats = sim.step(st, 0.01)
print("Hessians in step", target, len(H), flush=True)
rng = np.random.default_rng(0)
for k in range(1, len(H)):
    A, P = H[k], H[k - 1]
    b = A.createVecLeft(); b.setArray(rng.standard_normal(b.getLocalSize())); x = b.duplicate()
    res = []
    for rtol in (1e-6, 1e-10):
        ksp = PETSc.KSP().create(); ksp.setOperators(A, P); ksp.setType("cg")
        pc = ksp.getPC(); pc.setType("cholesky"); pc.setFactorSolverType("mumps")
        ksp.setTolerances(rtol=rtol, atol=0.0, max_it=500)
        ksp.setUp()
        t = time.process_time(); ksp.solve(b, x); dt = time.process_time() - t
        res.append(f"rtol {rtol:.0e}: {ksp.getIterationNumber()} its ({ksp.getConvergedReason()}) {dt*1e3:.0f} ms")
        ksp.destroy()
    same = A.getInfo()["nz_used"] == P.getInfo()["nz_used"]
    print(k, "same pattern" if same else "new pattern", "|", " | ".join(res), flush=True)
PY
