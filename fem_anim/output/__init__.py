"""Run outputs: the trajectory, per-step statistics and final state (gathered to rank 0), the
run directory that marks and locks what fem_anim owns, and the provenance of every number.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "CellGather": "files",
    "RENDER_PRODUCTS": "rundir",
    "RunDirectory": "files",
    "STATS_COLUMNS": "files",
    "StatsWriter": "files",
    "TrajectoryWriter": "files",
    "VertexGather": "files",
    "write_atomically": "rundir",
    "write_final": "files",
    "write_scene": "files",
    "WallClock": "provenance",
    "git_commit": "provenance",
    "mumps_version": "provenance",
    "software_versions": "provenance",
    "LOCK": "rundir",
    "MARKER": "rundir",
    "STAGING": "rundir",
    "check_not_in_use": "rundir",
    "claim": "rundir",
    "install": "rundir",
    "read_manifest": "rundir",
    "write_manifest": "rundir",
})
