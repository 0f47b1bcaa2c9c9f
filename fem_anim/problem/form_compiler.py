"""Compiling the step objective's UFL forms with FFCx, with history-free cache keys.

Every form of :class:`~fem_anim.problem.objective.EnergyProblem` goes through
:func:`compile_forms`, which compiles a dict of forms into one module with the project's
compiler flags (:data:`JIT_OPTIONS`).
"""

from __future__ import annotations

import os
import subprocess
import sysconfig

import ufl

from fem_anim import compat

__all__ = ["JIT_OPTIONS", "compile_forms", "gcc_flags"]


def gcc_flags(gcc_major: int) -> list[str]:
    """The gcc flags of the problem's kernels for a gcc of major version ``gcc_major``.

    ``-O2 -march=native``: the kernels run every Newton iteration (``-O1`` assembles
    markedly slower). ``-g0`` because CFFI compiles with Python's own CFLAGS, which carry
    ``-g``: debug information changes no instruction but slows gcc on large kernels
    (docs/cloth.md, "Cost"). From gcc 14 (Debian 13) also ``-fno-schedule-insns2``: tuning
    for the machine's CPU, gcc 14 can spend nearly all of a kernel's compile in its second
    instruction scheduling pass (gcc 12, Debian 12, does not), which an out-of-order CPU
    hardly needs; the assembly it gives up is small (docs/cloth.md, "Cost").

    Args:
        gcc_major: gcc's major version (0 when unknown: the flags of gcc 12).

    Returns:
        The flags, in the order they are given to gcc (after Python's own CFLAGS).
    """
    flags = ["-O2", "-g0", "-march=native"]
    return flags + ["-fno-schedule-insns2"] if gcc_major >= 14 else flags


def _gcc_major() -> int:
    """The major version of the C compiler CFFI's build runs (``CC``, else Python's), 0 if
    it cannot be asked."""
    cc = (os.environ.get("CC") or sysconfig.get_config_var("CC") or "gcc").split()
    try:
        out = subprocess.run([*cc, "-dumpversion"], capture_output=True, text=True,
                             timeout=60, check=False).stdout.strip()
        return int(out.split(".")[0])
    except (OSError, ValueError, subprocess.SubprocessError):
        return 0


#: FFCx/CFFI options of every kernel the problem compiles (forms and expressions): the
#: :func:`gcc_flags` of the machine's gcc.
JIT_OPTIONS = {"cffi_extra_compile_args": gcc_flags(_gcc_major())}

def compile_forms(forms: dict[str, ufl.Form]) -> dict:
    """Compile UFL forms with FFCx into one module, with cache keys independent of history.

    UFL caches a form's signature (its JIT cache key) when first asked. Compiling one form
    changes what UFL computes afterwards for another form built from the same expressions
    (here: the residual, built by ``ufl.derivative`` of the objective), so a run with a
    cold cache and one with a warm cache would name the residual differently and recompile
    it. Taking every signature before compiling anything makes the keys those of the forms
    as built, in every run.

    Args:
        forms: Name -> UFL form; the dict's order is the compiled module's order.

    Returns:
        Name -> compiled DOLFINx form (:func:`fem_anim.compat.compile_forms_together`).
    """
    for form in forms.values():
        form.signature()
    return compat.compile_forms_together(forms, JIT_OPTIONS)
