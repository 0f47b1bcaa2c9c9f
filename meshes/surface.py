"""The solid enclosed by a closed triangulated surface (STL, OBJ, PLY, ...), tetrahedralised."""

from __future__ import annotations

import math

import numpy as np

from fem_anim.meshes.common import name_body, set_element_size

__all__ = ["build_volume_from_surface"]


def build_volume_from_surface(model, points: np.ndarray, triangles: np.ndarray,
                              element_size: float, feature_angle: float = 40.0):
    """Remesh a closed surface with target edge ``element_size`` and fill it with tetrahedra.

    The triangles become a discrete gmsh surface, which is split into patches at edges
    sharper than ``feature_angle`` and into parametrisable pieces
    (``classifySurfaces``/``createGeometry``, as in gmsh's tutorial t13); the patches bound
    one volume. New surface nodes lie on the input triangles, so the enclosed volume is kept
    up to the chords cut across curved regions.

    The caller checks that the surface is closed and manifold
    (:func:`fem_anim.mesh.checks.check_surface`): gmsh's own failure on an open surface names
    no edge.

    Physical groups: ``body`` (tag 1) and ``surface`` (tag 1 in dimension 2).

    Args:
        model: ``gmsh.model`` of an initialised gmsh session.
        points: ``(n, 3)`` vertex coordinates (m).
        triangles: ``(m, 3)`` vertex indices of a closed, manifold, connected surface.
        element_size: Target edge length (m).
        feature_angle: Dihedral angle (degrees) above which an edge is kept as a feature.

    Returns:
        The model, meshed.
    """
    model.add("surface")
    surface = model.addDiscreteEntity(2)
    tags = np.arange(1, points.shape[0] + 1)
    model.mesh.addNodes(2, surface, tags, np.asarray(points, dtype=float).ravel())
    model.mesh.addElementsByType(surface, 2, [], (np.asarray(triangles) + 1).ravel())
    model.mesh.classifySurfaces(math.radians(feature_angle), True, True, math.pi)
    model.mesh.createGeometry()
    patches = [t for _, t in model.getEntities(2)]
    loop = model.geo.addSurfaceLoop(patches)
    body = model.geo.addVolume([loop])
    model.geo.synchronize()
    name_body(model, 3, [body])
    set_element_size(model, element_size)
    model.mesh.generate(3)
    return model
