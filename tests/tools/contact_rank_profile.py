"""Per-rank CPU seconds of the distributed contact on the contact bench's scene.

    mpirun -n R python tests/tools/contact_rank_profile.py H STEPS OUTDIR

Runs ``STEPS`` implicit-Euler steps of :func:`fem_anim.bench.contact_cost.pile_scene` (four
boxes meshed with element size ``H``) under cProfile with a CPU-time clock
(``time.process_time``) on every rank, and prints per rank and per step the CPU seconds of
ipctk's detection (``NormalCollisions.build``), its CCD, the cut to owned pairs
(:func:`fem_anim.contact.distribution.owned_collisions`) and the halo builds (the
``__init__`` of ``SurfaceHalo`` and of its ``VertexExchange``; and how many halos were
built), the Newton iterations, how many surface facets the rank's local mesh held after
each step and, at the end, how many facets of the whole surface have a vertex within
d_hat + k L of one of the rank's owned surface vertices (k = 2, 3, 5; L the longest surface
edge): the least a halo of that radius can hold. CPU seconds of these compute parts are
less distorted by a loaded machine than wall seconds (MPI waits are outside them). Each
step's displacement, in the order of the dof coordinates, is written to
``OUTDIR/u{step}_n{R}.npy`` and the Newton counts to ``OUTDIR/its_n{R}.txt``, so runs on
different rank counts or code versions compare entry by entry. Used for the 1 vs 2 ranks
table of ``docs/contact.md``.
"""

from __future__ import annotations

import cProfile
import pstats
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_anim.petsc_options import init_petsc

init_petsc([])

from fem_anim.bench.contact_cost import pile_scene  # noqa: E402
from fem_anim.scene.loading import load_scene  # noqa: E402
from fem_anim.simulation.loop import Simulation  # noqa: E402

#: (file suffix, function name) of the parts reported ("~": a built-in).
PARTS = (("~", "<built-in method ipctk.build>"),
         ("~", "<built-in method ipctk.compute_collision_free_stepsize>"),
         ("distribution.py", "owned_collisions"), ("distribution.py", "__init__"))


def main() -> int:
    comm = MPI.COMM_WORLD
    h, steps, out = float(sys.argv[1]), int(sys.argv[2]), Path(sys.argv[3])
    out.mkdir(exist_ok=True, parents=True)
    scene = out / "scene.toml"
    if comm.rank == 0:
        scene.write_text(pile_scene(h))
        (out / f"its_n{comm.size}.txt").write_text("")
    comm.Barrier()
    sim = Simulation(load_scene(scene), comm)
    ipc, V = sim.problem.ipc, sim.problem.V
    n = V.dofmap.index_map.size_local
    state = sim.initial_state()
    prof = cProfile.Profile(time.process_time)
    its, local = 0, []
    for step in range(steps):
        prof.enable()
        state, stats = sim.step(state, sim.scene["time"]["dt"])
        prof.disable()
        its += stats.newton_its
        local.append(len(ipc.halo.faces))
        X = comm.gather(V.tabulate_dof_coordinates()[:n], root=0)
        U = comm.gather(sim.problem.u.x.array.reshape(-1, 3)[:n].copy(), root=0)
        if comm.rank == 0:
            X, U = np.concatenate(X), np.concatenate(U)
            np.save(out / f"u{step}_n{comm.size}.npy", U[np.lexsort(np.round(X, 9).T[::-1])])
            with open(out / f"its_n{comm.size}.txt", "a") as f:
                f.write(f"{step + 1} {stats.newton_its}\n")
    table = pstats.Stats(prof).stats
    parts = []
    for suffix, name in PARTS:
        cpu = calls = 0
        for (file, _, function), (_, ncalls, _, cumulative, _) in table.items():
            if function == name and file.endswith(suffix):
                cpu, calls = cpu + cumulative, calls + ncalls
        parts.append(f"{name.replace('<built-in method ', '').rstrip('>')} "
                     f"{cpu / steps:.3f} s ({calls} calls)")
    surface = comm.allreduce(len(ipc.part.faces))
    builds = ipc.halo_builds
    # facets of the whole surface with a vertex near an owned surface vertex
    from scipy.spatial import cKDTree

    part, u_owned = ipc.part, ipc._u_owned()
    x = part.rest + part.face_exchange.fetch(u_owned)[np.searchsorted(part.face_vertices,
                                                                       part.faces)]
    every = np.concatenate(comm.allgather(x)).reshape(-1, 3)
    tree = cKDTree(part.owned_rest + u_owned[part.blocks])
    near = []
    for k in (2, 3, 5):
        d, _ = tree.query(every, distance_upper_bound=ipc.dhat + k * ipc.halo.longest)
        near.append(f"d_hat + {k} L: {int(np.isfinite(d).reshape(-1, 3).any(axis=1).sum())}")
    lines = comm.gather(f"rank {comm.rank}: CPU per step: " + ", ".join(parts)
                        + f"; halos built {builds}; Newton iterations per step "
                        f"{its / steps:.1f}; local facets {local} of {surface}; facets near "
                        "owned vertices " + ", ".join(near)
                        + f" (L = {ipc.halo.longest:.4f} m)", root=0)
    if comm.rank == 0:
        print("\n".join(lines), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
