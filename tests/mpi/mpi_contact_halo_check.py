"""Distributed IPC contact (:mod:`fem_anim.contact.distribution`) on any number of ranks.

Usage (``tests/test_contact_distribution.py`` runs it on 1 and 2 ranks and compares)::

    mpirun -n 2 python tests/mpi/mpi_contact_halo_check.py OUT.npz [--steps N (2)]

Two parallel bars (0.5 m long) thrown sideways at each other and two more far away,
with friction: a few implicit-Euler steps bring the pair into contact along its length. Then, at
the final state, the barrier energy (with friction), its gradient, the action H z of its
Hessian on two vectors z fixed by the dof coordinates, the CCD bound along a vector fixed
by the coordinates, the pair count and the minimum distance are evaluated; a second set at
a displacement moved past the halo's margin (so the halo is rebuilt mid-evaluation) and
one with a sweep wider than the halo (so the CCD builds a wider local mesh); a last set at
the final state rounded to 0.1 um, the same state to the bit on any number of ranks, with
each rank's count of owned pairs. Rank 0 writes
every per-dof array in the order of the dof coordinates, so runs on different rank counts
compare entry by entry, with the trajectory (u after each step) and, per rank, how many
facets its local mesh holds against the whole surface (and, at the final state, by body)
and how many halos it built.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim.petsc_options import init_petsc

init_petsc([])

from fem_anim.scene import load_scene  # noqa: E402
from fem_anim.simulation.loop import Simulation  # noqa: E402

COMM = MPI.COMM_WORLD

SCENE = """
name = "two_bars"
[time]
dt = 0.01
steps = 4
integrator = "implicit_euler"
[solver.petsc]
snes_atol = 1e-11
snes_rtol = 1e-14
[contact]
dhat = 0.004
friction = 0.3
"""
BODY = """
[[body]]
name = "{name}"
offset = [0, {y}, {z}]
rotation = [{turn}, 0, 0]
mesh = {{ shape = "box", size = [0.5, 0.04, 0.04], element_size = 0.02 }}
material = {{ youngs_modulus = 1e5, density = 1000 }}
initial = {{ velocity = [0.05, {v}, 0] }}
"""


def scene_text() -> str:
    text = SCENE
    # (on 2 ranks the partitioner gives bodies 0 and 2 to one rank, 1 and 3 to the other:
    # the pair's contact crosses ranks, and bodies 2 and 3 lie outside the other's halo)
    for k, (y, z, v, turn) in enumerate([(0.0, 0.0, 0.5, 0), (0.046, 0.005, -0.5, 3),
                                         (0.5, 0.0, 0.0, 0), (1.0, 0.0, 0.0, 0)]):
        text += BODY.format(name=f"b{k}", y=y, z=z, turn=turn, v=v)
    return text


def gather_sorted(sim, values: np.ndarray) -> np.ndarray | None:
    """Owned rows of a per-dof-block array, on rank 0 in the order of the dof coordinates."""
    V = sim.problem.V
    n = V.dofmap.index_map.size_local
    X = V.tabulate_dof_coordinates()[:n]
    rows = values.reshape(-1, 3)[:n]
    X, rows = COMM.gather(X, root=0), COMM.gather(rows, root=0)
    if COMM.rank:
        return None
    X, rows = np.concatenate(X), np.concatenate(rows)
    return rows[np.lexsort(np.round(X, 9).T[::-1])]


def field(sim, f) -> np.ndarray:
    """A local dof array (owned and ghosts) given by f(dof coordinates) -> (n, 3)."""
    X = sim.problem.V.tabulate_dof_coordinates()
    return np.ascontiguousarray(f(X)).ravel()


def evaluate(sim, label: str, out: dict) -> None:
    """Energy, gradient, H z, CCD bound, pairs and minimum distance at the current u."""
    ipc, V = sim.problem.ipc, sim.problem.V
    out[f"{label}_energy"] = ipc.energy()
    b = PETSc.Vec().createMPI((V.dofmap.index_map.size_local * 3, PETSc.DECIDE), comm=COMM)
    b.set(0.0)
    ipc.add_gradient(b, 0.7)
    out[f"{label}_gradient"] = gather_sorted(sim, b.array)
    n = V.dofmap.index_map.size_local * 3
    A = PETSc.Mat().createAIJ(((n, PETSc.DECIDE), (n, PETSc.DECIDE)), comm=COMM)
    A.setPreallocationNNZ(0)
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    A.setUp()
    ipc.add_hessian(A, 0.7)
    A.assemble()
    for k, f in enumerate((lambda X: np.sin(40 * X), lambda X: X[:, [1, 2, 0]] ** 2)):
        z, Hz = A.createVecs()
        z.array[:] = field(sim, f)[:n]
        A.mult(z, Hz)
        out[f"{label}_Hz{k}"] = gather_sorted(sim, Hz.array)
    y = field(sim, lambda X: 0.01 * np.cos(30 * X) * np.sign(np.sin(X[:, [1]] * np.pi
                                                                      / 0.046)))
    out[f"{label}_step_bound"] = ipc.step_bound(-y)
    out[f"{label}_wide_step_bound"] = ipc.step_bound(-20 * y)
    out[f"{label}_pairs"] = ipc.num_pairs
    out[f"{label}_min_distance"] = ipc.step_stats()["min_distance"]


def main() -> int:
    path, steps = Path(sys.argv[1]), 2
    if "--steps" in sys.argv:
        steps = int(sys.argv[sys.argv.index("--steps") + 1])
    with tempfile.TemporaryDirectory() as tmp:
        scene_path = Path(COMM.bcast(tmp if COMM.rank == 0 else None, root=0)) / "s.toml"
        if COMM.rank == 0:
            scene_path.write_text(scene_text())
        COMM.Barrier()
        sim = Simulation(load_scene(scene_path), COMM)
        COMM.Barrier()
    ipc, out = sim.problem.ipc, {}
    state = sim.initial_state()
    for k in range(steps):
        state, _ = sim.step(state, 0.01)
        out[f"u{k}"] = gather_sorted(sim, sim.problem.u.x.array)
    u_final = sim.problem.u.x.array.copy()
    evaluate(sim, "final", out)
    # what each rank's local mesh holds at the final state, by body: facets (own and
    # halo) and own facets
    local_body = ipc.halo.vertex_body[ipc.halo.faces[:, 0]]
    counts = np.stack([np.bincount(local_body, minlength=4),
                       np.bincount(ipc.part.body, minlength=4)])
    counts = COMM.gather(counts, root=0)
    # past the margin: the halo is rebuilt inside the next evaluation (a shear that changes
    # the pairs, and a translation along the bars by more than any margin, at most L)
    halo = ipc.halo
    sim.problem.u.x.array[:] += field(sim, lambda X: 0.008 * np.sign(X[:, [0]] - 0.25)
                                      * np.array([[0, 0, 1.0]]) + np.array([[0.1, 0, 0]]))
    evaluate(sim, "moved", out)
    out["rebuilt"] = int(ipc.halo is not halo)
    # the final state rounded to 0.1 um: the same bits on any number of ranks (the runs'
    # states differ by ~1e-16 m), still in contact along the bars (pairs across the ranks)
    sim.problem.u.x.array[:] = np.round(u_final, 7)
    evaluate(sim, "set", out)
    owned = COMM.gather(len(ipc.collisions), root=0)
    faces = COMM.gather(len(ipc.halo.faces), root=0)
    own = COMM.gather(len(ipc.part.faces), root=0)
    if COMM.rank == 0:
        out["local_faces"] = np.array(faces)
        out["set_owned_pairs"] = np.array(owned)
        out["final_local_bodies"] = np.array([c[0] for c in counts])
        out["final_own_bodies"] = np.array([c[1] for c in counts])
        out["surface_faces"] = sum(own)
        np.savez(path, **out)
        print(f"local facets per rank {faces} of {sum(own)}; halo rebuilt {out['rebuilt']}; "
              f"pairs {out['final_pairs']}, {out['moved_pairs']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
