"""Meshes: from a scene's ``[mesh]`` (gmsh builders, imported files, structured boxes) or its
``[[body]]`` list to one distributed DOLFINx mesh, with the checks that a mesh is usable (cell
quality, one connected body, a closed surface), the bodies' placement and the material regions;
a shell's surface in 3D (``shell_mesh``).
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "body_pins": "bodies",
    "body_regions": "bodies",
    "build_scene_mesh": "bodies",
    "rotation_matrix": "bodies",
    "build_mesh": "build",
    "mesh_arrays": "build",
    "FLAT": "checks",
    "MAX_COORDINATE": "checks",
    "cell_volumes": "checks",
    "check_cells": "checks",
    "check_surface": "checks",
    "DUPLICATE_TOLERANCE": "connectivity",
    "cell_components": "connectivity",
    "check_one_body": "connectivity",
    "duplicate_vertices": "connectivity",
    "gmsh_arrays": "gmsh_session",
    "gmsh_session": "gmsh_session",
    "MARKER_KEYS": "mesh_file",
    "MESHIO_TYPES": "mesh_file",
    "read_mesh_file": "mesh_file",
    "TRIMESH_SUFFIXES": "mesh_file",
    "cache_folder": "surface_repair",
    "clean_triangles": "surface_repair",
    "repair_surface_to_tets": "surface_repair",
    "MaterialMap": "regions",
    "MaterialSpec": "regions",
    "assign_materials": "regions",
    "local_cell_markers": "regions",
    "JointLayout": "joint_layout",
    "build_shell_mesh": "shell_mesh",
    "check_shell_surface": "shell_mesh",
    "CELL_NAMES": "simplex",
    "SimplexMesh": "simplex",
    "drop_unused_points": "simplex",
    "mesh_from_arrays": "simplex",
})
