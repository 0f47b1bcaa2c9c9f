"""The step minimiser (seed section 3.2) and its linear solvers (seed section 3.3).

:mod:`~fem_anim.solver.minimiser` sets up PETSc's SNES with the step objective, gradient and
Hessian and runs it; :mod:`~fem_anim.solver.stopping` decides when a step stops (residual
norms or Newton decrement, the round-off floor and its polish, the iteration budget) and
:mod:`~fem_anim.solver.solve_stats` records what it cost; :mod:`~fem_anim.solver.step_bounds`
shortens a Newton step before its line search (contact, inverted elements). Where Newton
picks its Hessian: :mod:`~fem_anim.solver.hessian_choice` (exact, shifted, filtered, auto),
with the remedies in :mod:`~fem_anim.solver.hessian_modification`, Newton-CG in a trust
region in :mod:`~fem_anim.solver.trust_region`, and how often it is rebuilt in
:mod:`~fem_anim.solver.hessian_reuse`. :mod:`~fem_anim.solver.presets` names the
linear-solver choices as PETSc options.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "FAILED_DIRECTION": "hessian_choice",
    "HESSIAN_KINDS": "hessian_choice",
    "HessianChoice": "hessian_choice",
    "MAX_AUTO_RESTARTS": "hessian_choice",
    "cg_probe": "hessian_choice",
    "FILTERS": "hessian_modification",
    "MODES": "hessian_modification",
    "RHO_TOLERANCE": "hessian_modification",
    "ShiftStrategy": "hessian_modification",
    "abs_psd": "hessian_modification",
    "filter_tangent": "hessian_modification",
    "model_ratio": "hessian_modification",
    "positive_definite": "hessian_modification",
    "project_psd": "hessian_modification",
    "trust_radius": "hessian_modification",
    "trust_region_choice": "hessian_modification",
    "HESSIAN_UPDATES": "hessian_reuse",
    "HessianReuse": "hessian_reuse",
    "Minimiser": "minimiser",
    "NONLINEAR_METHODS": "minimiser",
    "FORCING": "presets",
    "MIXED_ONLY_PRESETS": "presets",
    "NEWTON_DEFAULTS": "presets",
    "PRESETS": "presets",
    "SUMMARY": "presets",
    "describe_presets": "presets",
    "drop_replaced": "presets",
    "forcing_options": "presets",
    "parallel_note": "presets",
    "parallel_options": "presets",
    "preset_options": "presets",
    "SolveStats": "solve_stats",
    "MAX_FILTER_HALVINGS": "step_bounds",
    "bound_step": "step_bounds",
    "filter_inverting": "step_bounds",
    "step_limit": "step_bounds",
    "BUDGET_REASON": "stopping",
    "CONVERGED_REASONS": "stopping",
    "DECREMENT_REASON": "stopping",
    "POLISH_FAILED_REASON": "stopping",
    "ROUNDOFF_REASON": "stopping",
    "ROUNDOFF_ULPS": "stopping",
    "SADDLE_FLOOR": "stopping",
    "StoppingTest": "stopping",
    "accept_at_budget": "stopping",
    "at_objective_roundoff": "stopping",
    "finish_at_roundoff": "stopping",
    "polish": "stopping",
    "reason_name": "stopping",
    "resolution": "stopping",
    "NewtonCGTrustRegion": "trust_region",
    "direction_norm": "trust_region",
    "model_value": "trust_region",
    "set_radius": "trust_region",
})
