"""Several bodies in one scene: one DOLFINx mesh that is their union.

A scene's ``[[body]]`` tables each describe one body with the keys a one-body scene has
at the top level (``mesh``, ``material``, ``initial``, ``[[body.pin]]``,
``[[body.region]]``) and where it stands: the body's mesh (made by the same builders,
:func:`fem_anim.mesh.build.mesh_arrays`) is rotated by ``rotation`` (degrees about x, then y,
then z, i.e. x = R_z R_y R_x X + offset) and moved by ``offset`` (m). The bodies' meshes are
concatenated (vertex numbers offset) into one mesh whose cell marker is the body number
plus one, named by the body's name, so that

* the whole step stays one minimisation and one PETSc solve (seed eq. 4): the bodies are
  disjoint components of one mesh, coupled only by contact (:mod:`fem_anim.contact.ipc`);
* each body's material is a region of :mod:`fem_anim.mesh.regions` (the mesh group of its
  name), and a ``[[body.region]]`` box a region restricted to that body's cells;
* a body's pins act on that body's vertices only (boxes in scene coordinates).

Bodies must not overlap at rest: one lying inside another is refused here (rank 0, on
the input arrays); surfaces crossing or nearer than ``contact.dhat`` are refused when the
contact is set up.
"""

from __future__ import annotations


import numpy as np
from mpi4py import MPI

from fem_anim.errors import MeshError, SceneError
from fem_anim.mesh.build import build_mesh, mesh_arrays
from fem_anim.mesh.simplex import SimplexMesh, mesh_from_arrays

__all__ = ["body_regions", "body_pins", "build_scene_mesh", "rotation_matrix"]


def rotation_matrix(angles, d: int) -> np.ndarray:
    """R = R_z R_y R_x for angles (degrees) about x, y, z; in 2D one angle about z."""
    a = np.radians(np.asarray(angles if angles is not None else [0.0] * (3 if d == 3 else 1),
                              dtype=float))
    if d == 2:
        c, s = np.cos(a[0]), np.sin(a[0])
        return np.array([[c, -s], [s, c]])
    (cx, cy, cz), (sx, sy, sz) = np.cos(a), np.sin(a)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _body_arrays(scene, body: dict) -> tuple[np.ndarray, np.ndarray]:
    """Placed vertices and cells of one body's mesh (rank 0)."""
    cfg = body["mesh"]
    d = cfg["dim"]
    points, cells, _, _, _ = mesh_arrays(cfg, scene.base_dir)
    offset = np.zeros(d) if body["offset"] is None else np.asarray(body["offset"], float)
    return points @ rotation_matrix(body["rotation"], d).T + offset, cells


def _check_inside(points: np.ndarray, cells: np.ndarray, markers: np.ndarray,
                  names: list[str]) -> None:
    """No body lies inside another: one vertex of each tested against the others' cells."""
    for j in range(len(names)):
        probe = points[cells[markers == j + 1][0, 0]]
        other = cells[markers != j + 1]
        X = points[other]
        T = np.transpose(X[:, 1:] - X[:, :1], (0, 2, 1))  # columns X_k - X_0
        lam = np.linalg.solve(T, (probe - X[:, 0])[..., None])[..., 0]
        inside = np.all(lam >= 0.0, axis=1) & (lam.sum(axis=1) <= 1.0)
        if np.any(inside):
            k = int(markers[markers != j + 1][np.argmax(inside)]) - 1
            raise SceneError(f"body[{j}] ({names[j]}) and body[{k}] ({names[k]}) overlap at "
                             "rest (a vertex of the first lies inside the second); move them "
                             "apart with offset")


def build_scene_mesh(comm: MPI.Comm, scene) -> SimplexMesh:
    """The scene's mesh: the one ``[mesh]``, or the union of the ``[[body]]`` meshes
    (collective; errors are raised on every rank)."""
    bodies = scene["body"] if "body" in scene.data else []
    if not bodies:
        domain = build_mesh(comm, scene)
        if "contact" in scene.data:
            _collective(comm, lambda: _check_extent(domain, ["body"],
                                                    scene["contact"]["dhat"],
                                                    "shell" in scene.data))
        return domain
    d = bodies[0]["mesh"]["dim"]
    names = [b["name"] for b in bodies]
    points, cells, markers = np.empty((0, d)), np.empty((0, d + 1), np.int64), \
        np.empty(0, np.int32)

    def union():
        nonlocal points, cells, markers
        parts = [_body_arrays(scene, b) for b in bodies]
        start = np.cumsum([0] + [p.shape[0] for p, _ in parts])
        points = np.concatenate([p for p, _ in parts])
        cells = np.concatenate([c + s for (_, c), s in zip(parts, start)])
        markers = np.concatenate([np.full(c.shape[0], k + 1, np.int32)
                                  for k, (_, c) in enumerate(parts)])
        _check_inside(points, cells, markers, names)

    _collective(comm, union)
    domain = mesh_from_arrays(comm, points, cells, markers, "bodies",
                              {name: k + 1 for k, name in enumerate(names)})
    if "contact" in scene.data:
        _collective(comm, lambda: _check_extent(domain, names, scene["contact"]["dhat"]))
    return domain


def _check_extent(domain: SimplexMesh, names: list[str], dhat: float,
                  shell: bool = False) -> None:
    """contact.dhat must be smaller than every body (its least bounding-box extent, a shell's
    largest: a flat sheet has none across its plane; rank 0)."""
    points, cells, markers = domain.points, domain.cells, domain.cell_markers
    for k, name in enumerate(names):
        used = np.unique(cells[markers == k + 1]) if len(names) > 1 else np.unique(cells)
        spans = np.ptp(points[used], axis=0)
        extent = float(spans.max() if shell else spans.min())
        if not dhat < extent:
            raise SceneError(f"contact.dhat must be smaller than every body; body {name!r} "
                             f"is only {extent:.3g} m across, got {dhat}")


def _collective(comm: MPI.Comm, work) -> None:
    """Run ``work`` on rank 0 and raise its SceneError or MeshError on every rank."""
    error = None
    if comm.rank == 0:
        try:
            work()
        except (SceneError, MeshError) as err:
            error = (type(err), str(err))
    error = comm.bcast(error, root=0)
    if error:
        raise error[0](error[1])


def body_regions(scene) -> list[dict]:
    """The bodies as regions of :func:`fem_anim.mesh.regions.assign_materials`.

    Body k's material is the region of the mesh group named like the body; each of its
    ``[[body.region]]`` boxes follows, with the body's material as default and ``within``
    restricting it to the body's cells. Later entries win, as for ``[[region]]``.
    """
    keys = ("model", "youngs_modulus", "poisson_ratio", "density")
    out = []
    for body in scene["body"]:
        out.append(dict({k: body["material"][k] for k in keys}, name=body["name"], min=None,
                        max=None, within=None))
    for body in scene["body"]:
        for region in body["region"]:
            out.append(dict({k: body["material"][k] if region[k] is None else region[k]
                             for k in keys}, name=f"{body['name']}.{region['name']}",
                            min=region["min"], max=region["max"], within=body["name"]))
    return out


def body_pins(scene) -> list[tuple[str | None, str, dict]]:
    """(body name or None, key path, pin) of the scene's pins and every body's."""
    pins = [(None, f"pin[{i}]", pin) for i, pin in enumerate(scene["pin"])]
    for k, body in enumerate(scene.get("body") or []):
        pins += [(body["name"], f"body[{k}].pin[{i}]", pin) for i, pin in enumerate(body["pin"])]
    return pins
