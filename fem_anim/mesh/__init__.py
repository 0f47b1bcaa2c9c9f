"""Meshes: from a scene's ``[mesh]`` (gmsh builders, imported files, structured boxes) or its
``[[body]]`` list to one distributed DOLFINx mesh, with the checks that a mesh is usable (cell
quality, one connected body, a closed surface), the bodies' placement and the material regions.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "body_pins": "bodies",
    "body_regions": "bodies",
    "build_scene_mesh": "bodies",
    "rotation_matrix": "bodies",
    "SimplexMesh": "build",
    "build_mesh": "build",
    "cell_volumes": "build",
    "check_cells": "build",
    "check_surface": "build",
    "mesh_arrays": "build",
    "mesh_from_arrays": "build",
    "read_mesh_file": "build",
    "DUPLICATE_TOLERANCE": "connectivity",
    "cell_components": "connectivity",
    "check_one_body": "connectivity",
    "duplicate_vertices": "connectivity",
    "MaterialMap": "regions",
    "MaterialSpec": "regions",
    "assign_materials": "regions",
    "local_cell_markers": "regions",
})
