"""The compiler flags of the problem's kernels, and that they reach gcc
(fem_anim.problem.form_compiler).

gcc 14 (Debian 13) tuning for the machine's CPU spends most of a large kernel's compile in
its second instruction scheduling pass; ``JIT_OPTIONS`` turns that pass off there
(docs/cloth.md, "Cost"; docs/getting_started.md, the cold CI timing). The C compiler is
replaced by a script (``CC``, which the build honours) that writes down its arguments, then
runs gcc: the command line checked is the one that ran.
"""

from __future__ import annotations

import shutil

import ufl
from dolfinx import mesh
from mpi4py import MPI

from fem_anim.problem import form_compiler


def _recording_cc(folder) -> tuple[str, object]:
    """A C compiler command that appends its arguments (one line per call) to a log in
    ``folder`` and runs the system's gcc with them; returns the command and the log."""
    log = folder / "cc.log"
    script = folder / "cc"
    script.write_text(f'#!/bin/sh\necho "$*" >> "{log}"\nexec {shutil.which("gcc")} "$@"\n')
    script.chmod(0o755)
    return str(script), log


def test_the_second_scheduling_pass_is_off_from_gcc_14():
    """gcc 14's flags are gcc 12's plus ``-fno-schedule-insns2``; an unknown gcc (0) gets
    gcc 12's."""
    base = ["-O2", "-g0", "-march=native"]
    assert form_compiler.gcc_flags(12) == form_compiler.gcc_flags(0) == base
    assert form_compiler.gcc_flags(14) == form_compiler.gcc_flags(15) == \
        base + ["-fno-schedule-insns2"]


def test_compile_forms_gives_gcc_the_flags_of_its_version(tmp_path, monkeypatch):
    """The machine's gcc version is found, and ``compile_forms`` (every form of the step
    objective) compiles with its :func:`gcc_flags`, last on gcc's command line (after
    Python's own CFLAGS, so none of theirs overrides them)."""
    major = form_compiler._gcc_major()
    assert major >= 12
    flags = form_compiler.gcc_flags(major)
    assert form_compiler.JIT_OPTIONS["cffi_extra_compile_args"] == flags
    cc, log = _recording_cc(tmp_path)
    monkeypatch.setenv("CC", cc)
    cache = tmp_path / "cache"
    monkeypatch.setattr(form_compiler, "JIT_OPTIONS",
                        dict(form_compiler.JIT_OPTIONS, cache_dir=str(cache)))
    domain = mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    x = ufl.SpatialCoordinate(domain)
    compiled = form_compiler.compile_forms({"b": x[0] * x[1] * ufl.dx(domain=domain)})
    assert set(compiled) == {"b"}
    compiles = [line.split() for line in log.read_text().splitlines() if " -c " in line]
    assert len(compiles) == 1, log.read_text()  # the one module's C file
    assert compiles[0][-len(flags):] == flags
