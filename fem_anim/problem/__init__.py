"""The step objective bound to DOLFINx (seed section 3.1): inertia, elastic energy (from
``fem_anim.forms``), gravity, damping and obstacle contact compiled into one energy whose
gradient and Hessian are taken by ``ufl.derivative``; the pins and animated handles, the
per-point quadrature data, the terms assembled once, and the mixed (u, p) unknown.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "ConstantTerms": "constant_terms",
    "QuadraticTerm": "constant_terms",
    "PinMotion": "handles",
    "MixedFields": "mixed_space",
    "SchurPreconditioner": "mixed_space",
    "EVENTS": "objective",
    "EnergyProblem": "objective",
    "FILTERED_MODES": "objective",
    "compile_forms": "objective",
    "default_quadrature_degree": "objective",
    "QuadratureData": "quadrature",
})
