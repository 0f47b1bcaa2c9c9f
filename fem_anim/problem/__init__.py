"""The step objective bound to DOLFINx (seed section 3.1): :class:`EnergyProblem`
(``objective``) compiles inertia, elastic energy (from ``fem_anim.forms``), gravity, damping
and obstacle contact into one energy whose gradient and Hessian are taken by
``ufl.derivative``, and stages it each step. Its parts: the spaces, functions and measures
(``discretisation``), the UFL terms (``energy_terms``), the filtered Hessian
(``tangent_filter``), the pins (``pins``) and animated handles (``handles``), the matrices
(``matrices``), the reported energies (``reported_energies``), the form compiler
(``form_compiler``) and the assembly's log events (``events``); beside it the per-point quadrature
data (``quadrature``), the terms assembled once (``constant_terms``), the mixed (u, p)
unknown (``mixed_space``), a shell's membrane and bending energies (``shell_terms``) and its
wind drag (``wind_terms``).
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "ConstantTerms": "constant_terms",
    "QuadraticTerm": "constant_terms",
    "default_quadrature_degree": "discretisation",
    "JIT_OPTIONS": "form_compiler",
    "compile_forms": "form_compiler",
    "PinMotion": "handles",
    "MixedFields": "mixed_space",
    "SchurPreconditioner": "mixed_space",
    "EVENTS": "events",
    "EnergyProblem": "objective",
    "JointProblem": "joint_objective",
    "QuadratureData": "quadrature",
    "ShellEnergy": "shell_terms",
    "shell_measures": "shell_terms",
    "WindDrag": "wind_terms",
    "FILTERED_MODES": "tangent_filter",
})
