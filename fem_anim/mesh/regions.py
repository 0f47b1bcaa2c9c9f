"""Several materials in one body: which cells take which material (seed section 4.4).

A scene's ``[material]`` is the body's default; each ``[[region]]`` overrides some of its
keys (``model``, ``youngs_modulus``, ``poisson_ratio``, ``density``) on a set of cells:

* a **physical group** of the mesh, when the region gives no box: ``name`` is the group's
  name (gmsh ``$PhysicalNames``, or the groups the shape builders make, e.g. ``body``);
* a **box**, when it gives ``min`` and ``max``: the cells whose centroid lies in it (a new
  name, only a label).

Where regions overlap, the later entry in the scene wins, like a later layer of paint; a
region left without cells (none selected, or all taken by later ones) is an error, so
every declared region acts on the body. The elastic energy is then

    E(u) = sum_k int_{Omega_k} psi_k(F(u); mu(X), lmbda(X)) dV,

one integral per material *model* ``k`` in use (a UFL measure with cell tags), with the
Lame parameters and density as piecewise-constant (DG0) fields, so the number of kernels
does not grow with the number of regions. :func:`assign_materials` resolves the regions
on every rank for its local (owned and ghost) cells; it is collective.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fem_anim.errors import SceneError
from fem_anim.mesh.simplex import SimplexMesh

__all__ = ["MaterialMap", "MaterialSpec", "assign_materials", "local_cell_markers"]

KEYS = ("model", "youngs_modulus", "poisson_ratio", "density")


@dataclass(frozen=True)
class MaterialSpec:
    """One material: a model of :mod:`forms.material` and its parameters (SI units)."""

    model: str
    youngs_modulus: float
    poisson_ratio: float
    density: float


@dataclass
class MaterialMap:
    """The material of every local cell (owned and ghost, in DOLFINx's local numbering).

    Attributes:
        materials: Index 0 is the body's ``[material]``, index ``i + 1`` region ``i``'s.
        cell_material: Index into ``materials`` per local cell.
        models: The material models in use on any rank, sorted (the same on every rank).
        cell_model: Index into ``models`` per local cell (the cell tag of its integral).
    """

    materials: list[MaterialSpec]
    cell_material: np.ndarray
    models: list[str]
    cell_model: np.ndarray

    def cell_values(self, key: str) -> np.ndarray:
        """``key`` (a :class:`MaterialSpec` field) per local cell."""
        table = np.array([getattr(m, key) for m in self.materials], dtype=float)
        return table[self.cell_material]


def local_cell_markers(domain: SimplexMesh) -> np.ndarray:
    """The input cell markers (held on rank 0) of every local cell (collective).

    Each rank sends rank 0 the input indices of its cells
    (``topology.original_cell_index``) and gets their markers back.
    """
    comm = domain.mesh.comm
    wanted = np.asarray(domain.mesh.topology.original_cell_index, dtype=np.int64)
    requests = comm.gather(wanted, root=0)
    replies = [domain.cell_markers[r] for r in requests] if comm.rank == 0 else None
    return np.asarray(comm.scatter(replies, root=0), dtype=np.int32)


def _num_local_cells(mesh) -> tuple[int, int]:
    index_map = mesh.topology.index_map(mesh.topology.dim)
    return index_map.size_local, index_map.size_local + index_map.num_ghosts


def _select(domain: SimplexMesh, region: dict, i: int, markers) -> np.ndarray:
    """Boolean mask over local cells of region ``i`` (box by centroid, or mesh group)."""
    mesh = domain.mesh
    d = domain.dim
    if region["min"] is not None:
        if region["name"] in domain.marker_names:
            raise SceneError(f"region[{i}] ({region['name']}) gives min/max, but "
                             f"{region['name']!r} is a physical group of the mesh: rename the "
                             "box region, or drop min/max to use the group")
        _, n = _num_local_cells(mesh)
        centroids = dmesh.compute_midpoints(mesh, d, np.arange(n, dtype=np.int32))[:, :d]
        lo, hi = np.asarray(region["min"], float), np.asarray(region["max"], float)
        inside = np.all((centroids >= lo) & (centroids <= hi), axis=1)
        if region.get("within") is not None:  # a body's region: that body's cells only
            inside &= markers() == domain.marker_names[region["within"]]
        return inside
    if region["name"] not in domain.marker_names:
        known = ", ".join(sorted(domain.marker_names)) or "none: the mesh has no named groups"
        raise SceneError(f"region[{i}].name = {region['name']!r} is not a physical group of "
                         f"the mesh (known: {known}); to select cells by position give "
                         "min and max")
    return markers() == domain.marker_names[region["name"]]


def assign_materials(scene, domain: SimplexMesh, regions: list[dict] | None = None
                     ) -> MaterialMap:
    """Resolve ``[material]`` and ``[[region]]`` into a material per local cell (collective).

    ``regions`` replaces the scene's ``[[region]]`` list (the bodies of a multi-body scene,
    :func:`fem_anim.mesh.bodies.body_regions`); a region's optional ``within`` (a group name)
    restricts its box to that group's cells.

    Raises:
        SceneError: on every rank, for an unknown group name (listing the known ones), a
            box region named like a group, or a region that ends up with no cell.
    """
    comm = domain.mesh.comm
    owned, n = _num_local_cells(domain.mesh)
    regions = scene["region"] if regions is None else regions
    base = scene["material"]
    materials = [MaterialSpec(*(base[k] for k in KEYS))]
    cell_material = np.zeros(n, dtype=np.int32)
    selections = []
    cache: list[np.ndarray] = []

    def markers() -> np.ndarray:  # collective, so called on every rank or none
        if not cache:
            cache.append(local_cell_markers(domain))
        return cache[0]

    if any(r["min"] is None or r.get("within") is not None for r in regions):
        markers()
    for i, region in enumerate(regions):
        materials.append(MaterialSpec(*(base[k] if region[k] is None else region[k]
                                        for k in KEYS)))
        selected = _select(domain, region, i, markers)
        selections.append(selected)
        cell_material[selected] = i + 1
    _check_nonempty(comm, regions, selections, cell_material[:owned], owned)
    models_used = {materials[k].model for k in np.unique(cell_material[:owned])}
    models = sorted(set().union(*comm.allgather(models_used)))
    model_index = np.array([models.index(m.model) if m.model in models else -1
                            for m in materials], dtype=np.int32)
    return MaterialMap(materials, cell_material, models, model_index[cell_material])


def _check_nonempty(comm, regions, selections, owned_material, owned: int) -> None:
    """Every region keeps at least one (owned) cell somewhere; say who took them if not."""
    if not regions:
        return
    counts = np.array([[np.count_nonzero(s[:owned]) for s in selections],
                       [np.count_nonzero(owned_material == i + 1) for i in range(len(regions))]])
    overlaps = np.array([[np.count_nonzero(a[:owned] & b[:owned]) for b in selections]
                         for a in selections])
    counts = comm.allreduce(counts, op=MPI.SUM)
    overlaps = comm.allreduce(overlaps, op=MPI.SUM)
    for i, region in enumerate(regions):
        where = f"region[{i}] ({region['name']})"
        if counts[0, i] == 0:
            what = (f"no cell centroid lies in the box min {region['min']}, max "
                    f"{region['max']}") if region["min"] is not None else "the group has no cells"
            raise SceneError(f"{where} selects no cells: {what}")
        if counts[1, i] == 0:
            later = [f"region[{j}] ({regions[j]['name']})" for j in range(i + 1, len(regions))
                     if overlaps[i, j]]
            raise SceneError(f"{where}: all its cells are taken by {', '.join(later)} (where "
                             "regions overlap the later one wins)")
