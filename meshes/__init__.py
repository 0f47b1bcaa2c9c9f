"""Gmsh geometry builders (installed as ``fem_anim.meshes``; STYLE rule 3).

Each builder takes a ``gmsh.model``, adds its geometry and physical groups, meshes it
and returns the model. Builders never initialise or finalise gmsh: the caller owns the
session (see :func:`fem_anim.mesh.build_mesh`).
"""

from .box import build_box

__all__ = ["build_box", "BUILDERS"]

#: Scene ``mesh.shape`` -> builder.
BUILDERS = {"box": build_box}
