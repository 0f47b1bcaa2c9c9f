"""The step minimiser (seed section 3.2): PETSc SNES given the objective, gradient and
Hessian, its stopping tests and step bounds; which Hessian each Newton iteration uses
(exact, shifted, filtered, trust region), how often it is rebuilt, and the named linear-solver
presets of PETSc options (seed section 3.3).
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
    "BUDGET_REASON": "minimiser",
    "CONVERGED_REASONS": "minimiser",
    "Minimiser": "minimiser",
    "NONLINEAR_METHODS": "minimiser",
    "POLISH_FAILED_REASON": "minimiser",
    "ROUNDOFF_REASON": "minimiser",
    "SolveStats": "minimiser",
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
    "direction_norm": "trust_region",
    "model_value": "trust_region",
    "set_radius": "trust_region",
})
