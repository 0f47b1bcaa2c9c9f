"""Compiling the step objective's UFL forms with FFCx, with history-free cache keys.

Every form of :class:`~fem_anim.problem.objective.EnergyProblem` goes through
:func:`compile_forms`, which compiles a dict of forms into one module with the project's
compiler flags (:data:`JIT_OPTIONS`).
"""

from __future__ import annotations

import ufl

from fem_anim import compat

__all__ = ["JIT_OPTIONS", "compile_forms"]

#: FFCx/CFFI options of every kernel the problem compiles (forms and expressions). ``-g0``
#: because CFFI compiles with Python's own CFLAGS, which carry ``-g``: debug information
#: changes no instruction but slows gcc on large kernels (docs/cloth.md, "Cost").
#: ``-fno-schedule-insns2``: gcc 14 (Debian 13), tuning for the machine's CPU
#: (``-march=native``), can spend nearly all of a kernel's compile in its second instruction
#: scheduling pass, which an out-of-order CPU hardly needs (docs/cloth.md, "Cost").
JIT_OPTIONS = {"cffi_extra_compile_args": ["-O2", "-g0", "-march=native",
                                           "-fno-schedule-insns2"]}


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
