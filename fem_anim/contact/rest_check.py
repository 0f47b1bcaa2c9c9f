"""What is wrong, if anything, with the contact surfaces of a scene at rest.

IPC's barrier (:mod:`fem_anim.contact.ipc`) is +inf at contact and a minimisation can only
keep a collision-free start collision free: a scene whose bodies cross, or lie within the
barrier's reach of each other, at rest has no admissible first step. The check runs on each
rank's local contact mesh (its facets and halo, :mod:`fem_anim.contact.distribution`) and
the verdicts are combined, so every rank gives the same answer.
"""

from __future__ import annotations

import ipctk
import numpy as np
from mpi4py import MPI

__all__ = ["rest_problem"]


def rest_problem(comm: MPI.Comm, halo, x: np.ndarray, collisions, min_distance: float,
                 offset: float, dhat: float, names: list[str]) -> str | None:
    """The first problem of the surfaces at rest, as a message; None if there is none
    (collective).

    Pairs of one body within d_hat are legal (a thin part): the barrier is finite there.

    Args:
        comm: The communicator.
        halo: This rank's local mesh (``.mesh``, ``.vertex_body``).
        x: Its vertices' rest positions.
        collisions: The pairs nearer than d_hat on it (the pairs this rank owns).
        min_distance: The smallest distance of those pairs over all ranks (m; inf if none).
        offset: The minimum distance d_min kept (a shell's thickness; 0 for solids).
        dhat: The barrier's activation distance (m).
        names: The bodies' names by index (for messages).
    """
    mesh, body = halo.mesh, halo.vertex_body
    ids = [c.vertex_ids(mesh.edges, mesh.faces) for c in collisions]
    pairs = {tuple(sorted({int(body[v]) for v in vs if v >= 0})) for vs in ids}
    between = sorted(set().union(*comm.allgather({p for p in pairs if len(p) == 2})))
    if comm.allreduce(bool(ipctk.has_intersections(mesh, x)), op=MPI.LOR):
        if between:
            a, b = between[0]
            return (f"at rest, bodies {names[a]!r} and {names[b]!r} intersect; move them "
                    "apart (body offset)")
        return "at rest, the bodies' surfaces intersect (a mesh crosses itself)"
    if offset > 0 and np.isfinite(min_distance) and min_distance <= offset:
        return (f"at rest, two non-adjacent elements of a shell are {min_distance:.3g} m "
                f"apart, not more than its thickness {offset} m (the contact offset); make "
                "the shell thinner or its elements larger")
    if between:
        a, b = between[0]
        return (f"at rest, bodies {names[a]!r} and {names[b]!r} are closer than "
                f"contact.dhat = {dhat} m; move them apart (body offset) or reduce "
                "contact.dhat")
    return None
