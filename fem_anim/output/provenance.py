"""Where a run's numbers came from: the software stack, the solver options, the wall time.

Results depend on the stack (DOLFINx 0.5.2 on Debian 12 and 0.9.0 on Debian 13 mesh and
solve with different gmsh, PETSc and MUMPS releases), so ``summary.json`` records, beside
the physics, :func:`software_versions` (fem_anim and its git commit, Python, DOLFINx, UFL,
FFCx, basix, PETSc, petsc4py, MUMPS, gmsh, numpy, the MPI library and the number of
ranks), the merged PETSc options the step solver ran with, and the wall time split by
:class:`WallClock` (compile, mesh, stepping, output, render). Two runs are compared by
reading two files.
"""

from __future__ import annotations

import platform
import re
import subprocess
import time
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

__all__ = ["software_versions", "git_commit", "mumps_version", "WallClock"]

PACKAGE_DIR = Path(__file__).resolve().parent


def git_commit(path: Path = PACKAGE_DIR) -> str | None:
    """The commit of the git checkout holding a path.

    Args:
        path: A file or folder inside the checkout (default: this package).

    Returns:
        The HEAD commit (``+dirty`` if tracked files changed), or None outside a checkout.
    """
    try:
        head = subprocess.run(["git", "-C", str(path), "rev-parse", "HEAD"], text=True,
                              capture_output=True, timeout=10)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(path), "status", "--porcelain",
                                "--untracked-files=no"], text=True, capture_output=True,
                               timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")


def mumps_version() -> str | None:
    """The MUMPS release PETSc loaded, read off the shared library's name (Linux).

    Returns:
        The version string, or None if no MUMPS library is mapped into the process.
    """
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return None
    found = re.findall(r"libdmumps[-_.]?(\d+\.\d+(?:\.\d+)?)\.so", maps)
    return max(found, default=None)


def _distribution(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def software_versions(comm) -> dict:
    """The versions of everything a run's numbers depend on (call after PETSc is loaded).

    Args:
        comm: The run's communicator (its size is recorded).

    Returns:
        Package name -> version (None if not installed), plus the git commit, the MPI
        library and ``mpi_ranks``.
    """
    import basix
    import dolfinx
    import ffcx
    import gmsh
    import numpy
    import petsc4py
    import ufl
    from mpi4py import MPI
    from petsc4py import PETSc

    return {
        "fem_anim": _distribution("fem_anim"),
        "fem_anim_commit": git_commit(),
        "python": platform.python_version(),
        "dolfinx": dolfinx.__version__,
        "ufl": ufl.__version__,
        "ffcx": ffcx.__version__,
        "basix": basix.__version__,
        "petsc": ".".join(map(str, PETSc.Sys.getVersion())),
        "petsc4py": petsc4py.__version__,
        "mumps": mumps_version(),
        "gmsh": gmsh.__version__,
        "numpy": numpy.__version__,
        "mpi": MPI.Get_library_version().splitlines()[0].strip(" \x00"),
        "mpi_ranks": comm.size,
    }


class WallClock:
    """Wall time per phase of a run, in seconds (``with clock.phase("mesh"): ...``)."""

    PHASES = ("compile", "mesh", "setup", "stepping", "output", "render")

    def __init__(self):
        self.seconds: dict[str, float] = dict.fromkeys(self.PHASES, 0.0)

    @contextmanager
    def phase(self, name: str):
        """Add the wall time of a ``with`` block to a phase.

        Args:
            name: One of :attr:`PHASES`.
        """
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] += time.perf_counter() - start

    def add(self, name: str, seconds: float) -> None:
        """Add time measured elsewhere to a phase.

        Args:
            name: One of :attr:`PHASES`.
            seconds: The wall time to add.
        """
        self.seconds[name] += seconds

    def as_dict(self) -> dict[str, float]:
        """The phases for ``summary.json``.

        Returns:
            ``{phase}_s`` per phase and ``total_s``, rounded to microseconds.
        """
        out = {f"{k}_s": round(v, 6) for k, v in self.seconds.items()}
        out["total_s"] = round(sum(self.seconds.values()), 6)
        return out
