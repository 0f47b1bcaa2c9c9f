"""Export: a finished run in the formats animation packages read.

:mod:`~fem_anim.export.boundary` finds each body's boundary surface, wound outward;
:mod:`~fem_anim.export.run_reader` reads a run directory without DOLFINx;
:mod:`~fem_anim.export.usd_stage` writes a USD stage (one time-sampled mesh per body, the
obstacles, the frame rate, through Pixar's ``usd-core``);
:mod:`~fem_anim.export.mesh_sequence` writes OBJ or PLY files per body per frame;
:mod:`~fem_anim.export.export_command` is ``fem-anim export`` and keeps to the files fem_anim owns.
Public names load lazily.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "BodySurface": "boundary",
    "body_surfaces": "boundary",
    "boundary_faces": "boundary",
    "RunData": "run_reader",
    "read_run": "run_reader",
    "write_usd": "usd_stage",
    "export_staged_run": "usd_stage",
    "write_sequence": "mesh_sequence",
    "write_obj": "mesh_sequence",
    "write_ply": "mesh_sequence",
    "export_run": "export_command",
})
