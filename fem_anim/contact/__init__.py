"""Contact: the terms that keep bodies apart, added to the elastic energy in the step objective.

:mod:`~fem_anim.contact.obstacles` binds static obstacles (a ground plane, a sphere) as a
smooth barrier with lagged friction over the exterior facets, with the step bound that keeps
every trial point outside them; :mod:`~fem_anim.contact.ipc` wraps the IPC Toolkit for contact
between surfaces (bodies with each other and with themselves: barrier, continuous collision
detection; friction lagged at the step start, :mod:`~fem_anim.contact.lagged_friction`;
the check of the surfaces at rest, :mod:`~fem_anim.contact.rest_check`) under MPI, on the surface :mod:`~fem_anim.contact.contact_surface` gives
(a solid's boundary, or a shell's triangles kept its thickness apart) and
:mod:`~fem_anim.contact.p2_surface` puts on the displacement's dofs (P2 facets split on their
midpoint dofs); :mod:`~fem_anim.contact.intersection` is an independent check, on the cells
alone, that no frame of a run has an intersection. Public names load lazily.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "boundary_triangles": "intersection",
    "crossed_frames": "intersection",
    "crossing_pairs": "intersection",
    "enclosed_vertices": "intersection",
    "intersecting": "intersection",
    "is_shell": "contact_surface",
    "surface_entities": "contact_surface",
    "solid_bodies": "intersection",
    "surface_collision_mesh": "intersection",
    "surface_components": "intersection",
    "tetra10_cells": "intersection",
    "winding_numbers": "intersection",
    "surface_faces": "p2_surface",
    "IPCContact": "ipc",
    "JointIPCContact": "joint_surface",
    "LaggedFriction": "lagged_friction",
    "rest_problem": "rest_check",
    "KEEP_FRACTION": "obstacles",
    "ObstacleContact": "obstacles",
    "contact_quadrature": "obstacles",
})
