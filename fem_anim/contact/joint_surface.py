"""IPC contact on the union of two meshes' surfaces: a solid's boundary and a shell.

A shell (triangles in 3D) and a solid (tetrahedra) are two DOLFINx meshes with two
displacement spaces; their step is one minimisation over both unknowns (seed eq. 4 with
E = E_solid + E_shell + the barrier of :mod:`fem_anim.contact.ipc` between and within them;
docs/notes/shell_solid_coupling.md). :class:`JointIPCContact` is :class:`IPCContact` on the
*joint* surface: the solid's exterior facets and every triangle of the shell
(:func:`~fem_anim.contact.contact_surface.surface_entities` of each mesh), their vertices
numbered as the joint unknown's dof blocks (:class:`~fem_anim.mesh.joint_layout.JointLayout`:
rank r's blocks are its owned solid blocks followed by its owned shell blocks, starting
after all lower ranks' blocks of both spaces). Each rank then owns one contiguous range of
blocks, which is all the distributed barrier (:mod:`fem_anim.contact.distribution`) asks of
a numbering, so halo, pair ownership and exchanges are the solids' code.

ipctk 1.6 keeps one minimum distance d_min for every pair; here d_min is the shell's
thickness t: every surface is padded by t / 2, so two layers of the shell keep their
mid-surfaces t apart (the shell's self contact of :mod:`fem_anim.contact.contact_surface`,
unchanged), the shell's mid-surface stays t from the solid's boundary and two solid
faces t apart.
"""

from __future__ import annotations

import ipctk
import numpy as np

from fem_anim.contact.contact_surface import surface_entities
from fem_anim.contact.distribution import SurfacePartition
from fem_anim.contact.ipc import IPCContact
from fem_anim.contact.p2_surface import surface_faces
from fem_anim.errors import SceneError
from fem_anim.mesh.joint_layout import JointLayout

__all__ = ["JointIPCContact"]


class JointIPCContact(IPCContact):
    """The barrier of ``[contact]`` on the union of several meshes' contact surfaces.

    The joint unknown's local array is the concatenation of each space's owned dofs
    (:class:`~fem_anim.mesh.joint_layout.JointLayout`); only the surface's partition and
    the displacements it reads are built here, the rest is :class:`IPCContact`'s (its
    ``_start``), so every method (energy, ``add_gradient``, ``add_hessian``,
    ``step_bound``, ``stage``, ``finish_step``) works on the joint unknown.

    Args:
        cfg: The validated ``[contact]`` table (``self`` must be true: a shell's layers
            meet themselves).
        layout: The joint numbering of the parts' spaces.
        displacements: Each part's displacement Function (P1, 3 components), in the
            layout's order.
        pinned: Each part's pinned local dof indices (unblocked).
        cell_bodies: Each part's body index of each local cell (distinct across parts).
        body_names: Names of the bodies by index (for messages).
        offset: The minimum distance d_min of every pair (m; module docstring).

    Raises:
        SceneError: (collectively) if two bodies cross or are within ``dhat`` at rest, or
            two non-adjacent elements are nearer than ``offset``.
    """

    def __init__(self, cfg: dict, layout: JointLayout, displacements: list,
                 pinned: list[np.ndarray], cell_bodies: list[np.ndarray],
                 body_names: list[str], offset: float):
        spaces = [u.function_space for u in displacements]
        self.comm = comm = spaces[0].mesh.comm
        ipctk.set_num_threads(1)  # repeatable sums (fem_anim.contact.ipc)
        self.cfg, self.parts_u = cfg, displacements
        self.dhat, self.offset = float(cfg["dhat"]), float(offset)
        self.gdim = g = 3
        self.part_owned = [V.dofmap.index_map.size_local for V in spaces]
        start, self.n_owned = layout.start, layout.n_owned
        faces, rest, free, body, owned_X = [], [], [], [], []
        for k, (V, pins, cell_body) in enumerate(zip(spaces, pinned, cell_bodies)):
            mesh, index_map = V.mesh, V.dofmap.index_map
            tdim = mesh.topology.dim
            for a, b in ((tdim - 1, tdim), (tdim - 1, 0), (tdim, 0)):
                mesh.topology.create_connectivity(a, b)
            entity_vertices, entity_cells = surface_entities(mesh)
            c_to_v = mesh.topology.connectivity(tdim, 0).array.reshape(-1, tdim + 1)
            if len(V.dofmap.dof_layout.entity_dofs(1, 0)):  # dofs on edges: not P1
                raise SceneError("contact between a shell and a solid needs P1 displacements "
                                 "(element.degree = 1)")
            local_faces, _ = surface_faces(V, entity_vertices, c_to_v)
            n_local = index_map.size_local + index_map.num_ghosts
            X = V.tabulate_dof_coordinates()[:, :g]
            is_pinned = np.zeros(n_local * g, bool)
            is_pinned[pins] = True
            faces.append(layout.joint_of_local(k)[local_faces])
            rest.append(X[local_faces])
            free.append(~is_pinned.reshape(-1, g)[local_faces])
            body.append(np.asarray(cell_body)[entity_cells].astype(np.int64))
            owned_X.append(X[: index_map.size_local])
        faces, rest, free, body = (np.concatenate(a) for a in (faces, rest, free, body))
        self.unknown_rows = np.arange(self.n_owned, dtype=np.int64)[:, None] * g + np.arange(g)
        self.unknown_global = self.unknown_rows + start * g
        self.part = SurfacePartition(comm, faces, rest, free, body, np.zeros_like(faces),
                                     np.concatenate(owned_X), start, start + self.n_owned,
                                     True)
        self._start(body_names)

    def _u_owned(self) -> np.ndarray:
        """The owned displacement blocks of every part, in the joint order."""
        return np.concatenate([u.x.array.reshape(-1, self.gdim)[:n]
                               for u, n in zip(self.parts_u, self.part_owned)])
