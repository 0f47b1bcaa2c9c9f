"""``solver.mode``: named sets of solver keys, the trade of accuracy for speed in one word.

A mode fills the ``[solver]`` keys a scene (or ``--set``) did not give; every key given
explicitly still wins, as does ``--solver`` on the command line.

* ``"exact"`` (the default) fills ``hessian = "auto"`` (Newton's exact Hessian until it is
  indefinite, then a filtered one: :mod:`fem_anim.solver.hessian_modification`): Newton to
  the residual test of the preset (seed section 3.2, eq. 10).
* ``"preview"`` is one Newton step per time step, accepted unconverged when it decreased the
  step objective (``max_iterations = 1``, ``on_budget = "accept"``: the linearly implicit
  step of Baraff and Witkin, seed eq. 10 taken once from the predictor), solved by
  conjugate gradients with incomplete Cholesky (``cg-icc``) to a relative residual of 1e-4
  (``[solver.petsc] ksp_rtol``), with ``hessian = "auto"``: one Newton step is far from the
  converged step already, so solving its linear system to the preset's 1e-10 buys nothing,
  and ``auto`` lets CG survive the negative curvature of a strongly bent body. Every step it
  accepts without meeting the residual test is marked in ``stats.csv`` (reason 7,
  ``residual_ratio``), so the inexactness is visible.

A scene with contact (``[[obstacle]]`` tables, ``[contact]``, or several ``[[body]]`` tables,
which switch it on) gets none of the preview's keys: its steps are solved to the stopping test
as in ``"exact"``. One linearisation of the barrier per step does not keep the energy of an
impact bounded, whatever the linear solver: on ``demos/pile.toml`` the one-step preview gained
energy (with ``cg-icc``, whose incomplete Cholesky meets the pile's indefinite exact Hessian,
also with steps retried at half dt), and with MUMPS Cholesky it gained several times the energy
the run exchanged (docs/contact.md, "The preview on contact scenes", measured by
``bash docs/contact_scenes/measure_preview.sh``). The run's first line says so
(:func:`fem_anim.scene.contact_integrator.integrator_note`).

A mixed (u, p) scene that names no ``preset`` gets :data:`MIXED_DEFAULT_PRESET` (``ldlt``,
MUMPS LDL^T with pivoting: the saddle point is symmetric indefinite, which the default
``cholesky`` cannot factorise) in either mode, and keeps the exact Hessian; with contact it
also gets :data:`MIXED_CONTACT_PETSC`, PETSc's secant line search on the merit function
||r||^2/2 (``l2``): its saddle point has no objective, and at an impact backtracking (``bt``)
fails where the barrier's residual is far from linear over a step, and the step is retried at
half dt (measured in docs/contact.md, "P2 and mixed bodies in contact"); a scene whose regions
use several material models, or that names another ``method`` or a ``hessian_update``,
keeps the exact Hessian in either mode (``auto`` filters one model's tangent, and a kept
Hessian is never filtered). The measurements behind the preview's settings are in the
documentation's notes (``python -m fem_anim.bench.preview`` regenerates them).
"""

from __future__ import annotations

from typing import Any

from fem_anim.petsc_options import flatten_options

__all__ = ["MIXED_CONTACT_PETSC", "MIXED_DEFAULT_PRESET", "SOLVER_MODES", "apply_solver_mode"]

#: The preset a mixed (u, p) scene gets when it names none: a pivoting symmetric indefinite
#: factorisation, exact for the saddle point (``fem-anim solvers``).
MIXED_DEFAULT_PRESET = "ldlt"

#: The PETSc options a mixed (u, p) scene with contact gets when it sets none of them: the
#: secant line search on ||r||^2/2 (``l2``) instead of backtracking (``bt``), which fails at
#: impacts where the barrier's residual is far from linear over a step (module docstring).
MIXED_CONTACT_PETSC = {"snes_linesearch_type": "l2"}

#: ``solver.mode`` -> the ``[solver]`` keys it fills when the scene leaves them out.
SOLVER_MODES: dict[str, dict[str, Any]] = {
    "exact": {"hessian": "auto"},
    "preview": {"max_iterations": 1, "on_budget": "accept", "preset": "cg-icc",
                "hessian": "auto", "petsc": {"ksp_rtol": 1e-4}},
}


def apply_solver_mode(raw: dict[str, Any]) -> None:
    """Fill ``raw["solver"]`` (a parsed, not yet validated scene) from its ``mode``, in place.

    Args:
        raw: The scene's tables as parsed, overrides applied.

    Leaves anything malformed to the validator (an unknown mode, a non-table): it raises
    nothing.
    """
    solver = raw.setdefault("solver", {})
    mode = solver.get("mode", "exact") if isinstance(solver, dict) else None  # schema default
    if not isinstance(mode, str) or mode not in SOLVER_MODES:
        return
    element = raw.get("element")
    mixed = isinstance(element, dict) and element.get("formulation") == "mixed"
    keep_exact = mixed or solver.get("method", "newton") != "newton" or \
        solver.get("hessian_update", "every_iteration") != "every_iteration" or \
        _several_models(raw) or "shell" in raw or _shell_body(raw)
    if mixed:  # the saddle point needs ldlt, lu or schur (fem_anim.problem.mixed_space)
        solver.setdefault("preset", MIXED_DEFAULT_PRESET)
    if mode == "preview" and _has_contact(raw):  # converged steps (module docstring)
        mode = "exact"
    if mixed and _has_contact(raw):  # the merit function's line search (module docstring)
        _fill_petsc(solver, MIXED_CONTACT_PETSC)
    for key, value in SOLVER_MODES[mode].items():
        if key == "preset" and mixed:
            continue
        if key == "hessian" and keep_exact:
            continue
        if key == "petsc":
            _fill_petsc(solver, value)
            continue
        solver.setdefault(key, value)


def _shell_body(raw: dict[str, Any]) -> bool:
    """Whether a ``[[body]]`` of the parsed scene has a ``shell`` table (its step takes the
    exact Hessian: :mod:`fem_anim.scene.joint_rules`)."""
    bodies = raw.get("body")
    return isinstance(bodies, list) and any(isinstance(b, dict) and "shell" in b
                                            for b in bodies)


def _fill_petsc(solver: dict[str, Any], options: dict[str, Any]) -> None:
    """Add the mode's PETSc options the scene's ``[solver.petsc]`` does not set (flattened:
    ``ksp = {rtol = ...}`` sets ``ksp_rtol`` too)."""
    table = solver.setdefault("petsc", {})
    if not isinstance(table, dict):
        return  # the validator names it
    given = flatten_options(table)
    for name, value in options.items():
        if name not in given:
            table[name] = value


def _has_contact(raw: dict[str, Any]) -> bool:
    """Whether raw scene tables declare contact: obstacles, ``[contact]``, or several bodies
    (which switch ``[contact]`` on: :mod:`fem_anim.scene.validation`)."""
    bodies = raw.get("body")
    return bool(raw.get("obstacle")) or "contact" in raw or \
        (isinstance(bodies, list) and len(bodies) > 1)


def _several_models(raw: dict[str, Any]) -> bool:
    """Whether the scene's bodies or regions use more than one material model (raw scene
    tables; a body without a model counts as the default one)."""
    bodies = raw.get("body") if isinstance(raw.get("body"), list) else [raw]
    models = set()
    for body in bodies:
        if not isinstance(body, dict):
            continue
        material = body.get("material")
        model = material.get("model") if isinstance(material, dict) else None
        models.add(model if isinstance(model, str) else None)  # else: the validator names it
        regions = body.get("region")
        if isinstance(regions, list) and any(isinstance(r, dict) and "model" in r
                                             for r in regions):
            return True
    return len(models) > 1
