"""The contact surface of a body: the triangles (3D) or segments (2D) that IPC sees.

A solid's contact surface is its boundary: the exterior facets of its tetrahedra (3D) or
triangles (2D). A thin shell (a triangle mesh in 3D, topological dimension 2 < geometric
dimension 3, :mod:`fem_anim.mesh.shell_mesh`) has no inside, so its contact surface is the
mid-surface itself: every triangle, with the shell's thickness t as the offset of IPC's
codimensional contact (Li et al. 2021, "Codimensional Incremental Potential Contact": the
barrier acts on d - t, so two layers of cloth stop with their mid-surfaces t apart and each
keeps its half-thickness t / 2; seed eq. 4's E gains the barrier of
:mod:`fem_anim.contact.ipc`).
"""

from __future__ import annotations

import numpy as np
from dolfinx import mesh as dmesh

__all__ = ["is_shell", "surface_entities"]


def is_shell(mesh) -> bool:
    """Whether ``mesh`` is a shell's mid-surface (cells of lower dimension than the space)."""
    return mesh.topology.dim < mesh.geometry.dim


def surface_entities(mesh) -> tuple[np.ndarray, np.ndarray]:
    """The owned contact-surface entities of ``mesh`` and the cell each belongs to.

    Args:
        mesh: A DOLFINx mesh; the connectivities (tdim - 1, tdim), (tdim - 1, 0) and
            (tdim, 0) must exist.

    Returns:
        ``(vertices, cells)``: (entities, gdim) local vertex indices of each entity (a
        triangle in 3D, a segment in 2D; each entity on one rank only) and the local cell it
        belongs to (a shell's entity is its cell).
    """
    tdim = mesh.topology.dim
    c_to_v = mesh.topology.connectivity(tdim, 0).array.reshape(-1, tdim + 1)
    if is_shell(mesh):
        cells = np.arange(mesh.topology.index_map(tdim).size_local, dtype=np.int32)
        return c_to_v[cells], cells
    facets = dmesh.exterior_facet_indices(mesh.topology)
    f_to_v = mesh.topology.connectivity(tdim - 1, 0).array.reshape(-1, tdim)
    f_to_c = mesh.topology.connectivity(tdim - 1, tdim)
    return f_to_v[facets], f_to_c.array[f_to_c.offsets[facets]]
