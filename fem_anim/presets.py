"""Linear solver presets: named dictionaries of PETSc options (seed section 3.3).

Precedence (lowest to highest): :data:`NEWTON_DEFAULTS` < preset < scene
``[solver.petsc]`` < command line (:mod:`fem_anim.petsc_options`).

Direct presets use MUMPS, whose analysis applies a fill-reducing ordering (AMD/METIS
chosen automatically); the symbolic factorisation is reused while the sparsity pattern
is unchanged. MUMPS Cholesky on a general (not flagged SPD) matrix is an LDL^T
factorisation, so ``cholesky`` also survives an indefinite Newton Hessian.
"""

from __future__ import annotations

__all__ = ["NEWTON_DEFAULTS", "PRESETS", "preset_options", "describe_presets"]

#: Library defaults of the nonlinear solver: Newton with backtracking on the objective.
NEWTON_DEFAULTS: dict[str, str] = {
    "snes_type": "newtonls",
    "snes_linesearch_type": "bt",
    "snes_rtol": "1e-8",
    "snes_atol": "1e-12",
    "snes_stol": "0",
    "snes_max_it": "50",
}

PRESETS: dict[str, dict[str, str]] = {
    "cholesky": {"ksp_type": "preonly", "pc_type": "cholesky",
                 "pc_factor_mat_solver_type": "mumps"},
    "lu": {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"},
    "cg-icc": {"ksp_type": "cg", "pc_type": "icc", "ksp_rtol": "1e-10"},
}

SUMMARY = {
    "cholesky": "sparse Cholesky (MUMPS, LDL^T-capable), seed 3.3.1",
    "lu": "sparse LU with partial pivoting (MUMPS), seed 3.3.1",
    "cg-icc": "conjugate gradients with incomplete Cholesky, seed 3.3.2",
}


def preset_options(name: str) -> dict[str, str]:
    """The options of a preset.

    Raises:
        KeyError: with the known names, if ``name`` is not a preset.
    """
    if name not in PRESETS:
        raise KeyError(f"unknown solver preset {name!r} (known: {', '.join(PRESETS)})")
    return dict(PRESETS[name])


def describe_presets() -> str:
    """A human-readable list of the presets and their options (``fem-anim solvers``)."""
    lines = []
    for name, options in PRESETS.items():
        lines.append(f"{name}: {SUMMARY[name]}")
        lines += [f"    -{k} {v}" for k, v in options.items()]
    return "\n".join(lines)
