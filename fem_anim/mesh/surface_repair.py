"""Tetrahedra from an artist's surface: open, self-intersecting, with holes or duplicate faces.

fTetWild (Hu et al. 2020, "Fast Tetrahedral Meshing in the Wild", through ``pytetwild``)
meshes the solid a triangle soup encloses without asking the soup to be closed or manifold:
it inserts the triangles into a background tetrahedral mesh within an envelope of the
surface, optimises the tetrahedra's quality, and keeps those inside by the generalised
winding number of the input surface, so a hole is bridged, duplicated faces count once and
overlapping shells become their union. :func:`repair_surface_to_tets` first drops what
cannot be meshed (degenerate and duplicate triangles: fTetWild ends the process on them),
refuses a soup that encloses nothing, and runs fTetWild in a child process, so that a crash
inside it becomes one :class:`~fem_anim.errors.MeshError` rather than the end of the run.
The tetrahedra come back positively oriented (their volume, seed section 3: J > 0 at rest).

fTetWild is not deterministic (the same surface gives other tetrahedra from run to run, also
on one thread: wildmeshing/fTetWild issue 72), so each result is kept in a cache folder
(:func:`cache_folder`) under the hash of fTetWild's input: a scene run again, or resumed
from its checkpoint, gets the same tetrahedra.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from fem_anim.errors import MeshError
from fem_anim.mesh.checks import FLAT

__all__ = ["clean_triangles", "repair_surface_to_tets", "cache_folder", "ENVELOPE"]

#: fTetWild's envelope: the output surface lies within this fraction of the bounding box
#: diagonal of the input (fTetWild's default, 1e-3).
ENVELOPE = 1e-3
#: Seconds fTetWild may take before the mesh is given up.
TIMEOUT = 600.0


def clean_triangles(points: np.ndarray, triangles: np.ndarray, source: str) -> np.ndarray:
    """The triangles fTetWild can mesh: no repeated corner, no zero area, each face once.

    Args:
        points: ``(n, 3)`` vertex coordinates (repeated vertices already merged).
        triangles: ``(m, 3)`` vertex indices.
        source: What the surface is, for the message.

    Returns:
        The kept triangles, in their order (a face given twice, in either orientation, once).

    Raises:
        MeshError: if no triangle is left or the kept ones lie in one plane (nothing to fill),
            saying how many were dropped and why.
    """
    X = points[triangles]
    h = np.max(np.linalg.norm(X - X[:, [1, 2, 0]], axis=2), axis=1)
    area2 = np.linalg.norm(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), axis=1)
    flat = (area2 <= FLAT * h**2) | (h == 0.0)
    _, first = np.unique(np.sort(triangles, axis=1), axis=0, return_index=True)
    once = np.zeros(len(triangles), bool)
    once[first] = True
    kept = triangles[~flat & once]
    dropped = f"{int(flat.sum())} of its {len(triangles)} triangles have zero area"
    if len(kept) == 0:
        raise MeshError(f"{source}: nothing usable is left to fill with tetrahedra: {dropped}")
    used = points[np.unique(kept)]
    spread = np.linalg.svd(used - used.mean(axis=0), compute_uv=False)
    if len(used) < 4 or spread[2] <= 1e-9 * spread[0]:
        raise MeshError(f"{source}: nothing usable is left to fill with tetrahedra: its "
                        f"{len(kept)} usable triangles lie in one plane and enclose no volume "
                        f"({dropped})")
    return kept


def cache_folder() -> Path:
    """Where fTetWild's results are kept: ``$FEM_ANIM_CACHE``, else
    ``$XDG_CACHE_HOME/fem_anim``, else ``~/.cache/fem_anim`` (fem_anim's own folder: its
    files may be deleted at any time, they are made again)."""
    if os.environ.get("FEM_ANIM_CACHE"):
        return Path(os.environ["FEM_ANIM_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fem_anim"


def _cache_file(points: np.ndarray, triangles: np.ndarray, element_size: float) -> Path:
    """The cache file of one fTetWild input (points, triangles, edge, envelope, version)."""
    from importlib.metadata import version

    digest = hashlib.sha256()
    for part in (np.ascontiguousarray(points, np.float64), np.ascontiguousarray(triangles,
                                                                                  np.int64)):
        digest.update(part.tobytes())
    digest.update(f"{element_size!r} {ENVELOPE!r} {version('pytetwild')}".encode())
    return cache_folder() / f"tetwild-{digest.hexdigest()[:32]}.npz"


def repair_surface_to_tets(points: np.ndarray, triangles: np.ndarray, element_size: float,
                           source: str) -> tuple[np.ndarray, np.ndarray]:
    """Tetrahedralise the solid a triangle soup encloses with fTetWild (rank 0).

    Args:
        points: ``(n, 3)`` vertex coordinates (m).
        triangles: ``(m, 3)`` vertex indices: open, overlapping, duplicated faces allowed.
        element_size: fTetWild's target edge length (m).
        source: What the surface is, for messages.

    Returns:
        ``(points (p, 3), tets (q, 4))``, every tetrahedron of positive volume.

    Raises:
        MeshError: when nothing usable is left (:func:`clean_triangles`), fTetWild fails
            or crashes, or it finds no volume inside the surface.
    """
    kept = clean_triangles(points, triangles, source)
    cached = _cache_file(points, kept, element_size)
    try:
        with np.load(cached) as data:
            return _oriented(data["points"], data["tets"].astype(np.int64), source)
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):  # mesh again
        pass
    tet_points, tets = _run_tetwild(points, kept, element_size, source)
    try:  # a temporary name, renamed: a cache file is complete or absent
        cached.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tetwild-", suffix=".npz", dir=cached.parent)
        with os.fdopen(fd, "wb") as f:
            np.savez(f, points=tet_points, tets=tets)
        os.replace(tmp, cached)
    except OSError:  # a read-only home: the run goes on without the cache
        pass
    return _oriented(tet_points, tets, source)


def _oriented(tet_points: np.ndarray, tets: np.ndarray, source: str
              ) -> tuple[np.ndarray, np.ndarray]:
    """The tetrahedra with every one positively oriented (a swap of two vertices).

    Raises:
        MeshError: for no tetrahedra (nothing inside the surface).
    """
    if len(tets) == 0:
        raise MeshError(f"{source}: fTetWild found no volume inside the surface (is it a "
                        "sheet, or is mesh.element_size larger than the body?)")
    a, b, c, d = (tet_points[tets[:, k]] for k in range(4))
    negative = np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) < 0.0
    tets = tets.copy()
    tets[negative] = tets[negative][:, [0, 2, 1, 3]]
    return tet_points, tets


def _run_tetwild(points: np.ndarray, kept: np.ndarray, element_size: float, source: str
                 ) -> tuple[np.ndarray, np.ndarray]:
    """fTetWild in a child process (rank 0); its crash or failure is a MeshError."""
    with tempfile.TemporaryDirectory(prefix="fem_anim_tetwild_") as folder:
        given, made = Path(folder) / "surface.npz", Path(folder) / "tets.npz"
        np.savez(given, points=points, triangles=kept.astype(np.int32),
                 edge_length=element_size)
        env = {k: v for k, v in os.environ.items()
               if not k.startswith(("OMPI_", "PMIX_", "PMI_"))}  # not part of the MPI job
        env["PYTHONPATH"] = os.pathsep.join(
            [str(Path(__file__).resolve().parents[2])] + env.get("PYTHONPATH", "").split(
                os.pathsep)).rstrip(os.pathsep)
        try:  # in the temporary folder: fTetWild writes a file into its working directory
            child = subprocess.run([sys.executable, "-m", __name__, str(given), str(made)],
                                   capture_output=True, text=True, env=env, cwd=folder,
                                   timeout=TIMEOUT)
        except subprocess.TimeoutExpired:
            raise MeshError(f"{source}: fTetWild did not finish within {TIMEOUT:.0f} s (is "
                            "mesh.element_size too small?)") from None
        if child.returncode != 0 or not made.is_file():
            detail = " ".join(child.stderr.split()[-30:]) or f"exit code {child.returncode}"
            raise MeshError(f"{source}: fTetWild failed to fill the surface ({detail})")
        with np.load(made) as data:
            return data["points"], data["tets"].astype(np.int64)


def _main(given: str, made: str) -> None:
    """The child process: fTetWild on ``given``'s surface, tetrahedra into ``made``."""
    import pytetwild

    with np.load(given) as data:
        points, triangles = data["points"], data["triangles"]
        edge = float(data["edge_length"])
    tet_points, tets = pytetwild.tetrahedralize(
        np.asarray(points, np.float64), np.asarray(triangles, np.int32), edge_length_abs=edge,
        epsilon=ENVELOPE, num_threads=1, quiet=True)
    np.savez(made, points=np.asarray(tet_points, np.float64),
             tets=np.asarray(tets, np.int64).reshape(-1, 4))


if __name__ == "__main__":
    _main(*sys.argv[1:3])
