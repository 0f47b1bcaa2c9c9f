"""Bad input: a corpus of broken scene files, and a property test of the validator.

Issue "Reliability", bad-input part. Every case must end with exit code 2, one stderr line
``fem-anim: error: ...`` naming the key path and value (or the file), no traceback and
nothing written anywhere. Validation happens before dolfinx is imported, so the corpus runs
in-process through :func:`fem_anim.cli.main`; a representative subset (``fresh=True``) runs
again in a fresh ``python -m fem_anim`` to check the exit code and stderr for real.
The ``--set`` cases of ``tests/test_cli.py`` (``BAD_INPUT``) are not repeated here.
"""

from __future__ import annotations

import contextlib
import datetime
import io
import math
import os
import re
import subprocess
import tempfile
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import ROOT, clean_environment, fem_anim_command
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scenes import to_toml
from test_cli import BAD_INPUT

from fem_anim.cli import main
from fem_anim.errors import SceneError
from fem_anim.scene import Scene, load_scene
from fem_anim.scene.schema import (
    INTEGRATORS,
    MATERIAL_MODELS,
    MESH_SHAPES,
    NONLINEAR_METHODS,
    SCHEMA,
)

PREFIX = "fem-anim: error: "
MIXED = '[element]\ndegree = 2\nformulation = "mixed"\n'
CWD = "home/cwd"  # deep enough that "../.." from it still lies inside the test's tmp_path
PAYLOAD = "__import__('os').system('touch PWNED')"


@dataclass(frozen=True)
class Bad:
    """One bad input and the pieces its error line must contain."""

    id: str
    message: tuple[str, ...]
    scene: str | bytes | None = None  # written to scenes/scene.toml and passed as the scene
    args: tuple[str, ...] = ()  # more command-line arguments
    setup: Callable[[Path], list[str]] | None = None  # makes odd files, returns arguments
    output: bool = True  # pass -o OUT (False: the scene's own output path is under test)
    fresh: bool = False  # also run in a fresh process
    in_process: bool = True  # False for inputs that could hang the test process


def _fifo(tmp: Path) -> list[str]:
    os.mkfifo(tmp / "scene.fifo")
    return [str(tmp / "scene.fifo")]


def _unreadable(tmp: Path) -> list[str]:
    """A regular file that cannot be read: mode 000, or, as root (who reads every file), a
    link to /proc/self/mem, a regular file whose read at offset 0 fails (EIO) for anyone."""
    if os.geteuid() == 0:
        (tmp / "secret.toml").symlink_to("/proc/self/mem")
    else:
        (tmp / "secret.toml").write_text('name = "secret"\n')
        (tmp / "secret.toml").chmod(0)
    return [str(tmp / "secret.toml")]


def _symlink_out(tmp: Path) -> list[str]:
    """``output.directory = "link/run"`` where ``link`` points out of the working directory."""
    (tmp / CWD / "link").symlink_to(tmp / "elsewhere", target_is_directory=True)
    (tmp / "elsewhere").mkdir()
    (tmp / "scenes" / "link.toml").write_text('[output]\ndirectory = "link/run"\n')
    return [str(tmp / "scenes" / "link.toml")]


def _symlink_loop_out(tmp: Path) -> list[str]:
    (tmp / CWD / "loop").symlink_to("loop")
    (tmp / "scenes" / "loop.toml").write_text('[output]\ndirectory = "loop/run"\n')
    return [str(tmp / "scenes" / "loop.toml")]


def _absolute_out(tmp: Path) -> list[str]:
    scene = tmp / "scenes" / "abs.toml"
    scene.write_text(f'[output]\ndirectory = "{(tmp / "elsewhere").as_posix()}"\n')
    return [str(scene)]


def _output_is_a_file(tmp: Path) -> list[str]:
    (tmp / "blocker").write_text("not a directory\n")
    return ["-o", str(tmp / "blocker")]


def _user_folder(tmp: Path) -> list[str]:
    """A folder of the user's (not a run directory) given as -o."""
    (tmp / "mine" / "frames").mkdir(parents=True)
    (tmp / "mine" / "frames" / "holiday.png").write_bytes(b"user's picture")
    return ["-o", str(tmp / "mine")]


def _mesh_file(name: str, points, blocks) -> Callable[[Path], list[str]]:
    """Writes ``scenes/NAME`` (gmsh 2.2) for a scene with ``mesh.file = NAME``."""
    def setup(tmp: Path) -> list[str]:
        import meshio

        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            meshio.write(tmp / "scenes" / name, meshio.Mesh(points, blocks),
                         file_format="gmsh22", binary=False)
        return []
    return setup


_CUBE = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1]]
_TETS = [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]]
_CUBE2 = _CUBE + [[x + 2.0, y, z] for x, y, z in _CUBE]
_UNMERGED = [_CUBE[v] for tet in _TETS for v in tet]


def _mesh_scene(name: str) -> str:
    return f'[mesh]\nshape = "file"\nfile = "{name}"\n[time]\nsteps = 1\n'


PIN = "[[pin]]\nmin = [0, 0, 0]\nmax = [0.01, 1, 1]\n"
PLATE = "[mesh]\ndim = 2\nsize = [1.0, 0.2]\n"

#: One 0.1 m cube body moved by ``offset`` along x (format with name, offset).
BODY = ('[[body]]\nname = "{name}"\noffset = [{offset}, 0, 0]\n'
        'mesh = {{ shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.05 }}\n')

CORPUS = [
    # -- malformed TOML -------------------------------------------------------------------
    Bad("unterminated-string", ("scene.toml is not valid TOML",), 'name = "beam\n', fresh=True),
    Bad("duplicate-key", ("scene.toml is not valid TOML",), "[time]\ndt = 0.1\ndt = 0.2\n"),
    Bad("duplicate-table", ("scene.toml is not valid TOML",), "[time]\n[mesh]\n[time]\n"),
    Bad("missing-value", ("scene.toml is not valid TOML",), "[time]\ndt =\n"),
    Bad("unquoted-string", ("scene.toml is not valid TOML",), "[material]\nmodel = stvk\n"),
    Bad("deep-nesting", ("not valid TOML", "nested too deeply"),
        "[solver.petsc]\nx = " + "[" * 5000 + "]" * 5000 + "\n", fresh=True),
    Bad("5000-digit-integer", ("not valid TOML", "too many digits"),
        "[time]\nsteps = " + "9" * 5000 + "\n", fresh=True),
    # -- the file itself ------------------------------------------------------------------
    Bad("empty-file", ("scene.toml is empty",), ""),
    Bad("comments-only", ("scene.toml is empty",), "# a scene\n\n   \n"),
    Bad("binary-file", ("scene.toml is not UTF-8 text", "byte 0"),
        b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xd8", fresh=True),
    Bad("latin-1-string", ("scene.toml is not UTF-8 text",),
        'name = "Stahltr\xe4ger"\n'.encode("latin-1")),
    Bad("nul-bytes", ("scene.toml is not valid TOML",), b"name = \"a\x00b\"\n"),
    Bad("too-large", ("is larger than 1048576 bytes",), "# padding\n" * 120_000),
    Bad("directory", ("scene file", "is a directory"), setup=lambda tmp: [str(tmp / "scenes")],
        fresh=True),
    Bad("fifo", ("scene.fifo is not a regular file",), setup=_fifo, fresh=True,
        in_process=False),
    Bad("device", ("/dev/zero is not a regular file",), setup=lambda tmp: ["/dev/zero"],
        fresh=True, in_process=False),
    Bad("unreadable", ("secret.toml cannot be read",
                       "Input/output error" if os.geteuid() == 0 else "ermission denied"),
        setup=_unreadable),
    Bad("missing-directory", ("scene file", "nowhere/scene.toml does not exist"),
        setup=lambda tmp: [str(tmp / "nowhere" / "scene.toml")]),
    # -- wrong types, in every section ----------------------------------------------------
    Bad("name-int", ("name must be a string, got 3",), "name = 3\n"),
    Bad("mesh-dim-str", ("mesh.dim must be an integer, got '3'",), '[mesh]\ndim = "3"\n'),
    Bad("element-degree-float", ("element.degree must be an integer, got 1.0",),
        "[element]\ndegree = 1.0\n"),
    Bad("density-str", ("material.density must be a number, got '1000'",),
        '[material]\ndensity = "1000"\n'),
    Bad("dt-datetime", ("time.dt must be a number, got datetime.datetime(1979",),
        "[time]\ndt = 1979-05-27T07:32:00Z\n"),
    Bad("adaptive-int", ("time.adaptive must be true or false, got 1",), "[time]\nadaptive = 1\n"),
    Bad("gravity-str", ("gravity.acceleration must be a list, got 'down'",),
        '[gravity]\nacceleration = "down"\n'),
    Bad("damping-list", ("damping.alpha must be a number, got [0.1]",),
        "[damping]\nalpha = [0.1]\n"),
    Bad("pin-min-table", ("pin[0].min must be a list, got {'x': 0}",),
        "[[pin]]\nmin = {x = 0}\nmax = [1, 1, 1]\n"),
    Bad("method-list", ("solver.method must be a string, got ['newton']",),
        '[solver]\nmethod = ["newton"]\n'),
    Bad("petsc-str", ("solver.petsc must be a table, got 'ksp_type cg'",),
        '[solver]\npetsc = "ksp_type cg"\n'),
    Bad("every-float", ("output.every must be an integer, got 1.5",), "[output]\nevery = 1.5\n"),
    Bad("render-str", ("output.render must be true or false, got 'yes'",),
        '[output]\nrender = "yes"\n'),
    Bad("section-str", ("mesh must be a table, got 'box'",), 'mesh = "box"\n'),
    Bad("pin-table", ("pin must be an array of tables ([[pin]]), got {",),
        "[pin]\nmin = [0, 0, 0]\nmax = [1, 1, 1]\n"),
    Bad("pin-entry-int", ("pin[0] must be a table, got 1",), "pin = [1, 2]\n"),
    # -- booleans are not numbers ---------------------------------------------------------
    Bad("bool-youngs", ("material.youngs_modulus must be a number, got True",),
        "[material]\nyoungs_modulus = true\n", fresh=True),
    Bad("bool-steps", ("time.steps must be an integer, got False",), "[time]\nsteps = false\n"),
    Bad("bool-in-list", ("mesh.size must be a list of 2 or 3 numbers, got [1, True, 0.2]",),
        "[mesh]\nsize = [1, true, 0.2]\n"),
    # -- unknown keys and sections --------------------------------------------------------
    Bad("section-case", ("unknown section or key 'Material'",), "[Material]\ndensity = 1\n"),
    Bad("subtable", ("unknown key mesh.refine",), "[mesh.refine]\nlevels = 2\n"),
    Bad("pin-unknown-key", ("unknown key pin[0].fixed",), PIN + "fixed = true\n"),
    Bad("newline-in-key", ("unknown key time.'a\\nb'",), '[time]\n"a\\nb" = 1\n', fresh=True),
    Bad("long-key", ("unknown key material.'", "(1002 characters)"),
        "[material]\n" + '"' + "k" * 1000 + '" = 1\n'),
    # -- nonphysical and out-of-range values ----------------------------------------------
    Bad("size-zero", ("mesh.size must have all entries > 0, got [1, 0, 0.2]",),
        "[mesh]\nsize = [1, 0, 0.2]\n"),
    Bad("divisions-fraction", ("mesh.divisions must have all entries whole numbers >= 1",
                               "[30, 8.5, 8]"), "[mesh]\ndivisions = [30, 8.5, 8]\n"),
    Bad("divisions-zero", ("mesh.divisions must have all entries whole numbers >= 1",),
        "[mesh]\ndivisions = [30, 0, 8]\n"),
    Bad("divisions-length", ("mesh.divisions must have 3 entries", "[30, 8]"),
        "[mesh]\ndivisions = [30, 8]\n"),
    Bad("divisions-sphere", ("mesh.divisions = [4, 4, 4] is used with mesh.shape = \"box\" only",),
        '[mesh]\nshape = "sphere"\ndivisions = [4, 4, 4]\n'),
    Bad("divisions-huge", ("mesh.divisions = [10000, 10000, 10000] would make about",),
        "[mesh]\ndivisions = [10000, 10000, 10000]\n"),
    Bad("element-bigger-than-box", ("mesh.element_size must not exceed the box size 1.0",),
        "[mesh]\nelement_size = 2.0\n"),
    Bad("alpha-negative", ("damping.alpha must be >= 0, got -1",), "[damping]\nalpha = -1\n"),
    Bad("until-negative", ("pin[0].until must be >= 0, got -1.0",), PIN + "until = -1.0\n"),
    Bad("quadrature-13", ("element.quadrature_degree must be in 0..12, got 13",),
        "[element]\nquadrature_degree = 13\n"),
    Bad("steps-1e10", ("time.steps must be at most 1000000000, got 10000000000",),
        "[time]\nsteps = 10_000_000_000\n"),
    Bad("negative-zero-density", ("material.density must be > 0, got -0.0",),
        "[material]\ndensity = -0.0\n"),
    Bad("negative-zero-dt", ("time.dt must be > 0, got -0.0",), "[time]\ndt = -0.0\n"),
    Bad("huge-dt", ("time.dt must be at most 1e+150 in magnitude, got 1e+308",),
        "[time]\ndt = 1e308\n"),
    Bad("huge-in-list", ("gravity.acceleration[2] must be at most 1e+150 in magnitude",),
        "[gravity]\nacceleration = [0, 0, -1.7e308]\n"),
    Bad("huge-integer", ("time.steps must be at most 1e+150 in magnitude", "(401 characters)"),
        "[time]\nsteps = 1" + "0" * 400 + "\n"),
    Bad("subnormal-dt", ("time.dt must be 0 or at least 1e-150 in magnitude, got 4.94066e-324",),
        "[time]\ndt = 5e-324\n", fresh=True),
    # -- NaN and inf, anywhere ------------------------------------------------------------
    Bad("nan-youngs", ("material.youngs_modulus must be finite, got nan",),
        "[material]\nyoungs_modulus = nan\n"),
    Bad("inf-in-list", ("gravity.acceleration[2] must be finite, got -inf",),
        "[gravity]\nacceleration = [0, 0, -inf]\n"),
    Bad("nan-in-pin", ("pin[0].min[0] must be finite, got nan",),
        "[[pin]]\nmin = [nan, 0, 0]\nmax = [1, 1, 1]\n"),
    Bad("petsc-nan", ("solver.petsc.ksp_rtol must be finite, got nan",),
        "[solver.petsc]\nksp_rtol = nan\n", fresh=True),
    Bad("petsc-nested-inf", ("solver.petsc.ksp.atol must be finite, got inf",),
        "[solver.petsc]\nksp = {atol = inf}\n"),
    Bad("petsc-string-nan", ("solver.petsc.snes_rtol must be finite, got 'NaN'",),
        '[solver.petsc]\nsnes_rtol = "NaN"\n'),
    Bad("petsc-list", ("solver.petsc.ksp_rtol must be a string, a number or true/false, got [1",),
        "[solver.petsc]\nksp_rtol = [1e-8]\n"),
    Bad("petsc-bad-name", ("solver.petsc.'ksp type'", "PETSc option names"),
        '[solver.petsc]\n"ksp type" = "cg"\n'),
    # -- contradictory settings -----------------------------------------------------------
    Bad("p2-lumped", ('material.mass = "lumped" is not supported with element.degree = 2',),
        '[element]\ndegree = 2\n[material]\nmass = "lumped"\n'),
    Bad("hessian-lbfgs", ('solver.hessian = "shift"', 'solver.method = "lbfgs" uses none'),
        '[solver]\nmethod = "lbfgs"\nhessian = "shift"\n'),
    Bad("trust-region-filter-newtontr",
        ('solver.hessian = "trust_region_filter"', 'solver.method = "trust_region" has none'),
        '[solver]\nmethod = "trust_region"\nhessian = "trust_region_filter"\n'),
    Bad("forcing-lbfgs", ("solver.forcing = 'adaptive'", "solver.method = 'lbfgs' has none"),
        '[solver]\nmethod = "lbfgs"\nforcing = "adaptive"\n'),
    Bad("min-dt-over-dt", ("time.min_dt must not exceed time.dt = 0.01, got 0.1",),
        "[time]\ndt = 0.01\nmin_dt = 0.1\n"),
    Bad("pin-min-over-max", ("pin[0] (clamp) is an empty box", "min [0.5, 0, 0] exceeds max"),
        '[[pin]]\nname = "clamp"\nmin = [0.5, 0, 0]\nmax = [0.1, 1, 1]\n'),
    Bad("2d-center-in-3d", ("pin[0].center must have 3 entries for mesh.dim = 3, got [0, 0]",),
        PIN + "center = [0, 0]\n"),
    Bad("2d-origin-in-3d", ("mesh.origin must have 3 entries for mesh.dim = 3, got [0, 0]",),
        "[mesh]\norigin = [0, 0]\n"),
    Bad("3d-axis-in-2d", ("pin[0].axis is for mesh.dim = 3",),
        PLATE + "[[pin]]\nmin = [0, 0]\nmax = [0.01, 1]\naxis = [0, 0, 1]\n"),
    Bad("rotation-without-axis", ("pin[0].axis is required with pin[0].angular_velocity",),
        PIN + "angular_velocity = 1.0\n"),
    Bad("file-shape-without-file", ('mesh.file is required when mesh.shape = "file"',),
        '[mesh]\nshape = "file"\n'),
    # -- output paths: a scene cannot write outside the working directory ---------------------
    Bad("output-absolute", ("output.directory must be a relative path inside", "elsewhere"),
        setup=_absolute_out, output=False, fresh=True),
    Bad("output-dotdot", ("output.directory must not leave the working directory", "'../..'"),
        '[output]\ndirectory = "../.."\n', output=False, fresh=True),
    Bad("output-dotdot-inside", ("output.directory must not leave", "'runs/../../x'"),
        '[output]\ndirectory = "runs/../../x"\n', output=False),
    Bad("output-home", ("output.directory must be a relative path", "'~/runs'"),
        '[output]\ndirectory = "~/runs"\n', output=False),
    Bad("output-empty", ("output.directory must be a relative path", "got ''"),
        '[output]\ndirectory = ""\n', output=False),
    Bad("output-symlink", ("output.directory must not leave the working directory",
                           "symbolic link", "'link/run'"), setup=_symlink_out, output=False),
    Bad("output-symlink-loop", ("output.directory must be a path that resolves", "'loop/run'"),
        setup=_symlink_loop_out, output=False),
    Bad("name-traversal", ("name must be a simple file name", "got '../../escape'"),
        'name = "../../escape"\n', output=False, fresh=True),
    Bad("name-separator", ("name must be a simple file name", "got 'runs/beam'"),
        'name = "runs/beam"\n', output=False),
    Bad("name-dot", ("name must be a simple file name", "got '..'"), 'name = ".."\n',
        output=False),
    Bad("name-empty", ("name must be a simple file name", "got ''"), 'name = ""\n',
        output=False),
    Bad("name-long", ("name must be at most 1024 characters", "(100002 characters)"),
        'name = "' + "n" * 100_000 + '"\n', output=False),
    Bad("name-nul", ("name must not contain control characters, got 'beam\\x00'",),
        'name = "beam\\u0000"\n', output=False),
    Bad("pin-name-newline", ("pin[0].name must not contain control characters",),
        PIN + 'name = "wall\\nfem-anim: error: forged"\n'),
    Bad("petsc-viewer-file", ("solver.petsc.ksp_view_mat must not name a PETSc viewer",
                              "'binary:/tmp/matrix.bin'"),
        '[solver.petsc]\nksp_view_mat = "binary:/tmp/matrix.bin"\n', fresh=True),
    Bad("petsc-monitor-file", ("solver.petsc.snes.monitor must not name a PETSc viewer",),
        '[solver.petsc]\nsnes = {monitor = "ascii:../monitor.txt"}\n'),
    Bad("output-is-a-file", ("output directory", "blocker exists and is not a directory"),
        setup=_output_is_a_file, output=False),
    # -- scene files are data --------------------------------------------------------------
    Bad("payload-name", ("name must be a simple file name", PAYLOAD),
        f'name = "{PAYLOAD}"\n', fresh=True),
    Bad("payload-model", ("material.model must be one of", PAYLOAD),
        f'[material]\nmodel = "{PAYLOAD}"\n'),
    # -- obstacles (contact) ----------------------------------------------------------------
    Bad("obstacle-no-type", ("obstacle[0].type is required",),
        "[[obstacle]]\nnormal = [0, 0, 1]\n"),
    Bad("obstacle-bad-type", ("obstacle[0].type must be one of plane, sphere", "'cube'"),
        '[[obstacle]]\ntype = "cube"\n', fresh=True),
    Bad("obstacle-plane-no-normal", ('obstacle[0].normal is required for type = "plane"',),
        '[[obstacle]]\ntype = "plane"\n'),
    Bad("obstacle-zero-normal", ("obstacle[0].normal must be a nonzero vector", "[0, 0, 0]"),
        '[[obstacle]]\ntype = "plane"\nnormal = [0, 0, 0]\n'),
    Bad("obstacle-normal-2d", ("obstacle[0].normal must have 3 entries", "[0, 1]"),
        '[[obstacle]]\ntype = "plane"\nnormal = [0, 1]\n'),
    Bad("obstacle-sphere-no-center", ('obstacle[0].center is required for type = "sphere"',),
        '[[obstacle]]\ntype = "sphere"\nradius = 1\n'),
    Bad("obstacle-negative-radius", ("obstacle[0].radius must be > 0", "-1"),
        '[[obstacle]]\ntype = "sphere"\ncenter = [0, 0, -2]\nradius = -1\n'),
    Bad("obstacle-radius-on-plane", ('obstacle[0].radius does not apply to type = "plane"',),
        '[[obstacle]]\ntype = "plane"\nnormal = [0, 0, 1]\nradius = 1\n'),
    Bad("obstacle-zero-dhat", ("obstacle[0].dhat must be > 0", "0"),
        '[[obstacle]]\ntype = "plane"\nnormal = [0, 0, 1]\ndhat = 0\n'),
    Bad("obstacle-negative-friction", ("obstacle[0].friction must be >= 0", "-0.3"),
        '[[obstacle]]\ntype = "plane"\nnormal = [0, 0, 1]\nfriction = -0.3\n'),
    Bad("obstacle-nan-stiffness", ("obstacle[0].stiffness must be finite", "nan"),
        '[[obstacle]]\ntype = "plane"\nnormal = [0, 0, 1]\nstiffness = nan\n'),
    Bad("obstacle-unknown-key", ("unknown key obstacle[0].height",),
        '[[obstacle]]\ntype = "plane"\nnormal = [0, 0, 1]\nheight = 1\n'),
    Bad("obstacle-not-array", ("obstacle must be an array of tables",),
        '[obstacle]\ntype = "plane"\nnormal = [0, 0, 1]\n'),
    # -- element.formulation = "mixed" (nearly / exactly incompressible) ---------------------
    Bad("nu-half-displacement", ("material.poisson_ratio must be in (-1.0, 0.5)", "got 0.5",
                                 'needs element.formulation = "mixed"'),
        "[material]\npoisson_ratio = 0.5\n", fresh=True),
    *(Bad(f"mixed-{model}", (f"material.model = '{model}' has no volumetric split",
                             "neohookean, stable_neohookean, mooney_rivlin"),
          f'{MIXED}[material]\nmodel = "{model}"\n[solver]\npreset = "ldlt"\n')
      for model in ("linear", "stvk", "corotated")),
    Bad("mixed-lumped", (('material.mass = "lumped" is refused with element.formulation = '
                          '"mixed"'), "the pressure has no inertia"),
        f'{MIXED}[material]\nmass = "lumped"\n[solver]\npreset = "ldlt"\n'),
    Bad("mixed-p1", ('element.degree = 1 is refused with element.formulation = "mixed"',
                     "stabilisation"),
        '[element]\nformulation = "mixed"\n[solver]\npreset = "ldlt"\n'),
    Bad("mixed-cholesky", ("solver.preset = 'cholesky' cannot solve the saddle-point Hessian",
                           "ldlt, lu, schur"), f'{MIXED}[solver]\npreset = "cholesky"\n'),
    Bad("mixed-decrement", ("solver.stopping = 'decrement' is refused with element.formulation",
                            "saddle point"),
        f'{MIXED}[solver]\npreset = "ldlt"\nstopping = "decrement"\n'),
    Bad("schur-displacement", ("solver.preset = 'schur' splits displacement and pressure",),
        '[solver]\npreset = "schur"\n'),
    Bad("mooney-rivlin-displacement", (('material.model = "mooney_rivlin" exists only with '
                                        'element.formulation = "mixed"'),),
        '[material]\nmodel = "mooney_rivlin"\n'),
    # -- bodies and contact ---------------------------------------------------------------------
    Bad("bodies-overlap", ("body[1] (b) and body[0] (a) overlap at rest",),
        BODY.format(name="a", offset=0.0) + BODY.format(name="b", offset=0.05)),
    Bad("body-inside-body", ("body[1] (b) and body[0] (a) overlap at rest",),
        BODY.format(name="a", offset=0.0) + '[[body]]\nname = "b"\noffset = [0.04, 0.04, 0.04]\n'
        'mesh = { shape = "box", size = [0.02, 0.02, 0.02], element_size = 0.02 }\n'),
    Bad("bodies-within-dhat", ("bodies 'a' and 'b' are closer than contact.dhat = 0.01",),
        "[contact]\ndhat = 0.01\n" + BODY.format(name="a", offset=0.0)
        + BODY.format(name="b", offset=0.105)),
    Bad("contact-dhat-zero", ("contact.dhat must be > 0", "0"), "[contact]\ndhat = 0\n"),
    Bad("contact-dhat-larger-than-body", ("contact.dhat must be smaller than every body",
                                          "'b' is only 0.02 m across"),
        "[contact]\ndhat = 0.05\n" + BODY.format(name="a", offset=0.0)
        + '[[body]]\nname = "b"\noffset = [0.5, 0, 0]\n'
        'mesh = { shape = "box", size = [0.1, 0.1, 0.02], element_size = 0.02 }\n'),
    Bad("mixed-bodies-two-materials", ("body[1].material must equal body[0].material",),
        "[element]\ndegree = 2\nformulation = \"mixed\"\n[contact]\n"
        + BODY.format(name="a", offset=0.0) + BODY.format(name="b", offset=0.5).replace(
            "[[body]]", "[[body]]\nmaterial = { youngs_modulus = 2e5 }", 1)),
    Bad("contact-stiffness-word", ("contact.stiffness must be a number of Pa or \"adaptive\"",),
        '[contact]\nstiffness = "stiff"\n'),
    Bad("body-duplicate-name", ("body[1].name = 'a' is already used by body[0]",),
        BODY.format(name="a", offset=0.0) + BODY.format(name="a", offset=0.5)),
    Bad("body-with-top-level-mesh", ("mesh must not be given at the top level with [[body]]",),
        "[mesh]\nshape = \"box\"\n" + BODY.format(name="a", offset=0.0)),
    Bad("body-pin-misses-body", ("body[1].pin[0] (pin): the box", "no mesh vertex of body 'b'"),
        BODY.format(name="a", offset=0.0) + BODY.format(name="b", offset=0.5)
        + "[[body.pin]]\nmin = [-1, -1, -1]\nmax = [0.2, 1, 1]\n"),
    # -- --set on a scene file --------------------------------------------------------------
    Bad("set-key-into-list", ("--set pin.first.min: pin is a list; give an entry number",),
        PIN, args=("--set", "pin.first.min=[0, 0, 0]"), fresh=True),
    # -- folders of the user's, command-line PETSc options, mesh files -------------------------
    Bad("output-users-folder", ("output directory", "mine is not empty and is not a fem-anim run "
                                "directory"), "[time]\nsteps = 1\n", setup=_user_folder,
        output=False, fresh=True),
    Bad("output-name-too-long", ("File name too long",), "[time]\nsteps = 1\n",
        setup=lambda tmp: ["-o", str(tmp / ("x" * 300))], output=False),
    Bad("resume-elsewhere", ("--resume", "and -o", "name different directories"),
        "[time]\nsteps = 1\n", args=("--resume", "elsewhere")),
    Bad("solver-empty", ("--solver needs a preset name", "got ''"), "[time]\nsteps = 1\n",
        args=("--solver", "")),
    Bad("solver-blank", ("--solver needs a preset name",), "[time]\nsteps = 1\n",
        args=("--solver", "  ")),
    Bad("cli-petsc-nan", ("PETSc option -ksp_rtol must be finite, got 'nan'",),
        "[time]\nsteps = 1\n", args=("-ksp_rtol", "nan"), fresh=True),
    Bad("cli-petsc-inf", ("PETSc option -snes_atol must be finite, got 'inf'",),
        "[time]\nsteps = 1\n", args=("-snes_atol", "inf")),
    Bad("petsc-word-for-number", ("PETSc option -snes_rtol must be a number, got 'abc'",),
        "[time]\nsteps = 1\n", args=("-snes_rtol", "abc")),
    Bad("petsc-max-it-word", ("PETSc option -ksp_max_it must be a number, got 'many'",),
        "[time]\nsteps = 1\n", args=("-ksp_max_it", "many")),
    Bad("petsc-unknown-pc", ("PETSc rejected the solver options", "-pc_type nosuch"),
        "[time]\nsteps = 1\n", args=("-pc_type", "nosuch")),
    Bad("log-view-no-folder", ("-log_view :/no/such/dir/f", "cannot be created",
                               "/no/such/dir"),
        "[time]\nsteps = 1\n", args=("-log_view", ":/no/such/dir/f"), fresh=True),
    Bad("ksp-view-no-folder", ("-ksp_view ascii:/no/such/dir/k.txt", "cannot be created"),
        "[time]\nsteps = 1\n", args=("-ksp_view", "ascii:/no/such/dir/k.txt")),
    Bad("mesh-file-without-shape", ("mesh.file = 'x.msh' is not used with mesh.shape = 'box'",
                                    'set mesh.shape = "file"'),
        '[mesh]\nfile = "x.msh"\n', fresh=True),
    Bad("mesh-mixed-cells", ("mixed.msh mixes cell types", "1 hexahedron cells"),
        _mesh_scene("mixed.msh"), setup=_mesh_file("mixed.msh", _CUBE2, [
            ("tetra", _TETS), ("hexahedron", [[8, 9, 11, 10, 12, 13, 15, 14]])])),
    Bad("mesh-unmerged", ("unmerged.msh is not one body", "6 disconnected pieces",
                          "16 duplicate vertices"),
        _mesh_scene("unmerged.msh"), setup=_mesh_file(
            "unmerged.msh", _UNMERGED, [("tetra", [[4 * c + k for k in range(4)]
                                                   for c in range(6)])]), fresh=True),
    Bad("mesh-two-pieces", ("two.msh is not one body", "2 disconnected pieces"),
        _mesh_scene("two.msh"), setup=_mesh_file(
            "two.msh", _CUBE2, [("tetra", _TETS + [[v + 8 for v in t] for t in _TETS])])),
    Bad("mesh-huge-coordinates", ("huge.msh: vertex 1", "beyond 1e+100 in magnitude"),
        _mesh_scene("huge.msh"), setup=_mesh_file(
            "huge.msh", [[1e200 * c for c in p] for p in _CUBE], [("tetra", _TETS)]),
        fresh=True),  # in a fresh process: no numpy overflow warning before the line
    Bad("mesh-tiny", ("tiny.msh: the mesh is 1e-200 across",),
        _mesh_scene("tiny.msh"), setup=_mesh_file(
            "tiny.msh", [[1e-200 * c for c in p] for p in _CUBE], [("tetra", _TETS)])),
]


def _argv(case: Bad, tmp: Path) -> list[str]:
    """Lay out ``tmp/{home/cwd,scenes}``, write the case's files; the arguments after ``run``."""
    (tmp / CWD).mkdir(parents=True)
    (tmp / "scenes").mkdir()
    argv = []
    if case.scene is not None:
        scene = tmp / "scenes" / "scene.toml"
        if isinstance(case.scene, bytes):
            scene.write_bytes(case.scene)
        else:
            scene.write_text(case.scene, encoding="utf-8")
        argv.append(str(scene))
    if case.setup is not None:
        argv += case.setup(tmp)
    if case.output:
        argv += ["-o", str(tmp / "out")]
    return argv + ["-q", *case.args]


def _tree(tmp: Path) -> dict[str, int]:
    """Every path below ``tmp`` (symbolic links not followed) with its size."""
    return {str(p.relative_to(tmp)): p.lstat().st_size for p in tmp.rglob("*")}


def assert_rejected(code: int, stderr: str, message: tuple[str, ...], before: dict, tmp: Path):
    """Exit 2, one line ``fem-anim: error: ...`` with every piece of ``message``, no files."""
    assert code == 2, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    assert lines[0].startswith(PREFIX), lines[0]
    for piece in message:
        assert piece in lines[0], (piece, lines[0])
    assert "Traceback" not in stderr
    assert not (tmp / "out").exists()
    assert _tree(tmp) == before  # nothing written: not -o, not out/<name>, not elsewhere
    assert not list(tmp.rglob("PWNED"))


def run_fresh(argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """``python -m fem_anim`` in a new process (60 s: a validation error takes ~0.5 s)."""
    return subprocess.run(fem_anim_command() + argv, cwd=cwd, capture_output=True, text=True,
                          timeout=60, env=clean_environment(), check=False)


def test_corpus_is_new_and_large_enough():
    assert len(CORPUS) >= 30
    assert len({c.id for c in CORPUS}) == len(CORPUS)
    assert all(c.scene is not None or c.setup is not None for c in CORPUS)  # files, not --set
    assert not [c.id for c in CORPUS if list(c.args) in [args for args, _ in BAD_INPUT]]
    assert sum(c.fresh for c in CORPUS) >= 10


@pytest.mark.parametrize("case", [c for c in CORPUS if c.in_process], ids=lambda c: c.id)
def test_bad_input_in_process(case, tmp_path, monkeypatch, capsys):
    argv = ["run"] + _argv(case, tmp_path)
    monkeypatch.chdir(tmp_path / CWD)
    before = _tree(tmp_path)
    code = main(argv)
    captured = capsys.readouterr()
    assert captured.out == ""
    assert_rejected(code, captured.err, case.message, before, tmp_path)


@pytest.mark.parametrize("case", [c for c in CORPUS if c.fresh], ids=lambda c: c.id)
def test_bad_input_fresh_process(case, tmp_path):
    argv = ["run"] + _argv(case, tmp_path)
    before = _tree(tmp_path)
    r = run_fresh(argv, tmp_path / CWD)
    assert r.stdout == ""
    assert_rejected(r.returncode, r.stderr, case.message, before, tmp_path)


# -- scene files are data ---------------------------------------------------------------------
def test_strings_in_a_scene_are_never_evaluated(tmp_path, monkeypatch):
    """Code in every free-text field and in keys stays a plain string (or is rejected)."""
    monkeypatch.chdir(tmp_path)
    scene = tmp_path / "scene.toml"
    scene.write_text(f'''
[mesh]
shape = "file"
file = "{PAYLOAD}"
[[pin]]
name = "{PAYLOAD}"
min = [0, 0, 0]
max = [0.01, 1, 1]
[solver]
preset = "{PAYLOAD}"
[solver.petsc]
ksp_type = "{PAYLOAD}"
''')
    loaded = load_scene(scene)
    assert loaded["mesh"]["file"] == PAYLOAD and loaded["pin"][0]["name"] == PAYLOAD
    assert loaded["solver"]["preset"] == PAYLOAD
    assert loaded["solver"]["petsc"]["ksp_type"] == PAYLOAD
    pinned = load_scene(scene, [f'pin.0.name="{PAYLOAD}"', "solver.petsc.pc_type='os.system'"])
    assert pinned["pin"][0]["name"] == PAYLOAD
    for bad in ([f"name={PAYLOAD}"], [f'"{PAYLOAD}"=1'], [f"time.dt={PAYLOAD}"]):
        with pytest.raises(SceneError):
            load_scene(scene, bad)
    scene.write_text(f'"{PAYLOAD}" = 1\n')
    with pytest.raises(SceneError, match="unknown section or key"):
        load_scene(scene)
    assert not list(tmp_path.rglob("PWNED")) and not (ROOT / "PWNED").exists()


# -- property test: any TOML in, a Scene or a SceneError out ---------------------------------
def scene_text(data: dict) -> str:
    return "".join(f"{to_toml(k)} = {to_toml(v)}\n" for k, v in data.items())


TEXT = st.text(st.characters(exclude_categories=("Cs",)), max_size=12)
KEYS = st.one_of(TEXT, st.sampled_from(["ksp_type", "type", "snes", "min", "name", "x"]))
#: Values that broke, or could break, a validator: edge numbers, paths, viewers, code.
NASTY = st.sampled_from([
    math.nan, math.inf, -math.inf, -0.0, 5e-324, 1e308, 1e151, 1e-151, 0, -1, 2**63,
    -(10**400), 10**10, True, False, "", "nan", "-inf", "../..", "/tmp/x", "a/b", "~",
    "ascii:log.txt", "binary", "wall\nfem-anim: error: forged", "\x00", "k" * 2000, PAYLOAD,
    [], {}, [math.nan], [1, True], [[1]], {"": 1}, {"a b": {"c": []}},
    datetime.date(1979, 5, 27)])
SCALARS = st.one_of(st.integers(-(10**20), 10**20), st.floats(), st.booleans(), TEXT,
                    st.dates(), st.datetimes(), st.times())
JUNK = st.recursive(st.one_of(NASTY, SCALARS), lambda inner: st.lists(inner, max_size=4)
                    | st.dictionaries(KEYS, inner, max_size=4), max_leaves=12)
BAD = st.one_of(NASTY, JUNK)
NUMBER = st.one_of(st.floats(1e-3, 2.0), st.sampled_from([0.25, 0.5, 1e5]))
VECTOR = st.lists(NUMBER, min_size=2, max_size=3)
CHOICES = {("mesh", "shape"): MESH_SHAPES, ("material", "model"): MATERIAL_MODELS,
           ("time", "integrator"): INTEGRATORS, ("solver", "method"): NONLINEAR_METHODS,
           ("solver", "stopping"): ("norm", "decrement"),
           ("solver", "hessian"): ("exact", "shift", "project"),
           ("material", "mass"): ("consistent", "lumped"), ("solver", "preset"): ("cholesky",),
           ("output", "directory"): ("runs/a", ".", "out/x"), ("mesh", "dim"): (2, 3),
           ("element", "degree"): (1, 2), ("material", "poisson_ratio"): (0.0, 0.3, 0.45)}


def plausible(section: str, key: str, kind) -> st.SearchStrategy:
    """Values of the right type, mostly valid."""
    if (section, key) in CHOICES:
        return st.sampled_from(CHOICES[section, key])
    if kind is str:
        return st.from_regex(r"[a-z][a-z0-9_]{0,8}", fullmatch=True)
    if kind is int:
        return st.integers(1, 4)
    if kind is bool:
        return st.booleans()
    if kind is list:
        return VECTOR
    if kind is dict:
        return st.dictionaries(st.from_regex(r"[a-z_]{1,10}", fullmatch=True),
                               st.one_of(SCALARS, st.dictionaries(KEYS, SCALARS, max_size=2)),
                               max_size=3)
    return NUMBER


def table(section: str, junk: bool) -> st.SearchStrategy:
    """A section with a random subset of its keys; ``junk``: any value, and unknown keys."""
    values = {k: plausible(section, k, key.kind) for k, key in SCHEMA[section].items()}
    if junk:
        values = {k: st.one_of(v, JUNK) for k, v in values.items()} | {"bogus": JUNK}
    return st.fixed_dictionaries({}, optional=values)


SECTIONS = [s for s in SCHEMA if s and s not in ("pin", "obstacle")]
WILD_SCENES = st.fixed_dictionaries({}, optional={
    "name": st.one_of(st.from_regex(r"[a-z][a-z_]{0,8}", fullmatch=True), JUNK),
    **{s: st.one_of(table(s, True), JUNK) for s in SECTIONS},
    "pin": st.one_of(st.lists(table("pin", True), max_size=2), JUNK),
    "wind": JUNK,
})
PLAUSIBLE_SCENES = st.fixed_dictionaries({}, optional={
    "name": st.from_regex(r"[a-z][a-z_]{0,8}", fullmatch=True),
    **{s: table(s, False) for s in SECTIONS},
    "pin": st.lists(table("pin", False), max_size=2)})


@st.composite
def mutated_scenes(draw) -> dict:
    """A plausible scene with one or two values replaced by junk (reaches the deep checks)."""
    scene = draw(PLAUSIBLE_SCENES)
    for _ in range(draw(st.integers(1, 2))):
        section = draw(st.sampled_from(["name", "wind", "pin", *SECTIONS]))
        if section in ("name", "wind"):
            scene[section] = draw(BAD)
            continue
        key = draw(st.sampled_from([*SCHEMA[section], "bogus"]))
        if section == "pin":
            pins = scene.setdefault("pin", [])
            pins.append({}) if not pins else None
            pins[0][key] = draw(BAD)
        else:
            scene.setdefault(section, {})[key] = draw(BAD)
    return scene


SCENES = st.one_of(mutated_scenes(), WILD_SCENES)
OVERRIDES = st.lists(st.one_of(
    st.builds(lambda s, k, v: f"{s}.{k}={to_toml(v)}",
              st.sampled_from([*SECTIONS, "pin", "pin.0", "name", "wind"]),
              st.sampled_from(["dt", "steps", "model", "min", "0", "first.min", "petsc.x"]),
              JUNK),
    TEXT), max_size=2)


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("hypothesis")


def _load(path: Path, overrides: list[str]) -> Scene | SceneError:
    try:
        return load_scene(path, overrides)
    except SceneError as err:
        return err


PROPERTY = settings(max_examples=200, deadline=2000, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@PROPERTY
@given(data=SCENES, overrides=OVERRIDES)
def test_any_scene_gives_a_scene_or_a_scene_error(scratch, data, overrides):
    text = scene_text(data)
    tomllib.loads(text)  # the junk is valid TOML: it reaches the validator, not just the parser
    path = scratch / "scene.toml"
    path.write_text(text, encoding="utf-8")
    result = _load(path, overrides)  # anything else than these two propagates and fails
    if isinstance(result, Scene):
        assert not result.data["output"]["directory"] or not result.data["output"][
            "directory"].startswith(("/", ".."))
    else:  # one line of reasonable length, whatever the input (odd text is quoted)
        message = str(result)
        assert not any(ord(c) < 32 or c in "\x7f\x85\u2028\u2029" for c in message), message
        assert 0 < len(message) < 2000


@PROPERTY
@given(raw=st.one_of(st.binary(max_size=200),
                     st.lists(st.sampled_from(["[time]", "[[pin]]", "dt = ", "1e400", "nan",
                                               '"', "[", "]", "{", "}", "=", "\n", "x", ".",
                                               "\\u0000", "'''", "\xff", "\nx = " + "[" * 3000,
                                               "\nx = " + "9" * 5000, "\ufeff"]), max_size=30)
                     .map("".join).map(lambda s: s.encode("utf-8", "surrogatepass"))))
def test_any_bytes_give_a_scene_or_a_scene_error(scratch, raw):
    path = scratch / "raw.toml"
    path.write_bytes(raw)
    _load(path, [])


@settings(max_examples=5, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(data=SCENES)
def test_generated_bad_scenes_exit_2_in_a_fresh_process(data):
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / CWD).mkdir(parents=True)
        scene = tmp / "scene.toml"
        scene.write_text(scene_text(data), encoding="utf-8")
        with contextlib.chdir(tmp / CWD):  # output.directory is checked against the cwd
            expected = _load(scene, [])
        assume(isinstance(expected, SceneError))  # a valid scene would run a simulation
        before = _tree(tmp)
        r = run_fresh(["run", str(scene), "-o", str(tmp / "out"), "-q"], tmp / CWD)
        assert_rejected(r.returncode, r.stderr, (), before, tmp)
        shown = "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(expected))
        assert r.stderr.strip() == PREFIX + shown


@pytest.mark.parametrize("overrides, message", [
    (["mesh.size=[1e4, 1, 1]"], "would make about 4.8e+08 cells"),
    (['mesh.shape="torus"', "mesh.minor_radius=0.2"], "mesh.minor_radius must be < mesh.radius"),
])
def test_mesh_size_rules(overrides, message):
    with pytest.raises(SceneError, match=re.escape(message)):
        load_scene(None, overrides)


def test_unwritable_output_directory_is_one_clear_error(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    code = main(["run", "-q", "--set", "time.steps=1", "--set", "mesh.element_size=0.1",
                 "-o", str(blocker / "sub")])
    assert code == 2
    err = capsys.readouterr().err
    assert "output directory" in err and "cannot be written" in err and "Traceback" not in err
