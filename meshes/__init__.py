"""Gmsh geometry builders (installed as ``fem_anim.meshes``).

Each builder takes a ``gmsh.model``, adds its geometry and physical groups, meshes it
and returns the model. Builders never initialise or finalise gmsh: the caller owns the
session (see :func:`fem_anim.mesh.build.build_mesh`). Every builder names the physical group
``body`` (tag 1) of its cells and ``surface`` (tag 1, one dimension lower) of its whole
boundary, plus the parts of the boundary a scene may refer to (``xmin``, ``side``, ...).
:func:`structured_box` (numpy, no gmsh) cuts a box into a regular grid of simplices
(``mesh.divisions``).

:data:`BUILDERS` calls them uniformly as ``BUILDERS[shape](model, mesh)`` with a scene's
``[mesh]`` table ``mesh``; :data:`BUILDER_KEYS` says which keys each one reads.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from fem_anim.meshes.box import build_box
from fem_anim.meshes.capsule import build_capsule
from fem_anim.meshes.cylinder import build_cylinder
from fem_anim.meshes.sheet import build_sheet, structured_sheet
from fem_anim.meshes.sphere import build_sphere
from fem_anim.meshes.structured import structured_box
from fem_anim.meshes.surface import build_volume_from_surface
from fem_anim.meshes.torus import build_torus

__all__ = [
    "BUILDERS",
    "BUILDER_KEYS",
    "build_box",
    "build_capsule",
    "build_cylinder",
    "build_sheet",
    "build_sphere",
    "build_torus",
    "build_volume_from_surface",
    "structured_box",
    "structured_sheet",
]

#: Scene ``mesh.shape`` -> the ``[mesh]`` keys its builder takes (as keyword arguments).
BUILDER_KEYS: dict[str, tuple[str, ...]] = {
    "box": ("size", "element_size", "origin"),
    "sphere": ("radius", "element_size", "origin", "dim"),
    "cylinder": ("radius", "length", "element_size", "origin", "dim"),
    "torus": ("radius", "minor_radius", "element_size", "origin", "dim"),
    "capsule": ("radius", "length", "element_size", "origin", "dim"),
    "sheet": ("size", "element_size", "origin", "triangulation"),
}

_FUNCTIONS = {"box": build_box, "sphere": build_sphere, "cylinder": build_cylinder,
              "torus": build_torus, "capsule": build_capsule, "sheet": build_sheet}


def _from_mesh_table(shape: str) -> Callable:
    builder, keys = _FUNCTIONS[shape], BUILDER_KEYS[shape]

    def build(model, mesh: Mapping):
        return builder(model, **{key: mesh[key] for key in keys})

    build.__name__ = build.__qualname__ = f"{builder.__name__}_from_mesh_table"
    build.__doc__ = f"``{builder.__name__}(model, **{{k: mesh[k] for k in {keys}}})``."
    return build


#: Scene ``mesh.shape`` -> ``builder(model, mesh)``, ``mesh`` the scene's ``[mesh]`` table.
BUILDERS: dict[str, Callable] = {shape: _from_mesh_table(shape) for shape in _FUNCTIONS}
