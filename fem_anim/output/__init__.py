"""Output: what a run leaves on disk and where its numbers came from.

:mod:`~fem_anim.output.files` gathers displacements and cell values to rank 0 in input order
and writes ``stats.csv``, ``final.vtu`` and ``scene.json`` through a staging area;
:mod:`~fem_anim.output.dof_gather` does it for every dof of a P1
or P2 field (the trajectory's ``output.fields``); :mod:`~fem_anim.output.trajectory` writes
the trajectory (XDMF + HDF5) so that a kill at any moment leaves it continuable;
:mod:`~fem_anim.output.rundir` marks, locks and installs a run
directory so fem_anim only ever replaces files it wrote, and
:mod:`~fem_anim.output.products` keeps that promise for every other command writing into
a folder a user names; :mod:`~fem_anim.output.provenance`
records the software stack and the wall time per phase for ``summary.json``. Public names
load lazily.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "CellGather": "files",
    "DofGather": "dof_gather",
    "RENDER_PRODUCTS": "rundir",
    "RunDirectory": "files",
    "STATS_COLUMNS": "files",
    "StatsWriter": "files",
    "body_numbers": "files",
    "TrajectoryWriter": "trajectory",
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
    "foreign_files": "rundir",
    "STAGING_PREFIX": "products",
    "check_may_write": "products",
    "installed_by_this_process": "products",
    "staged_products": "products",
    "write_product": "products",
})
