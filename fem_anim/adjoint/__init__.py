"""Gradients through the simulation: the discrete adjoint of the time-stepping.

:mod:`~fem_anim.adjoint.parameters` binds what can be differentiated (material constants,
density, damping, the initial velocity, spin and displacement, friction coefficients) into
the step objective; :mod:`~fem_anim.adjoint.tape` runs and keeps the forward states (in
memory, on disk, or checkpointed by the binomial schedule of
:mod:`~fem_anim.adjoint.schedule` and recomputed); :mod:`~fem_anim.adjoint.backward` sweeps
back through the steps with the exact Hessian of each converged step;
:mod:`~fem_anim.adjoint.objectives` says what is measured;
:mod:`~fem_anim.adjoint.differentiate` ties them into
:func:`gradient`.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "ParameterSet": "parameters",
    "Tape": "tape",
    "record_forward": "tape",
    "choose_storage": "tape",
    "BinomialSchedule": "schedule",
    "BackwardSweep": "backward",
    "CentreOfMassTarget": "objectives",
    "FormFunctional": "objectives",
    "Objective": "objectives",
    "PointTarget": "objectives",
    "StateFunctional": "objectives",
    "TrajectoryMatch": "objectives",
    "AdjointModel": "differentiate",
    "gradient": "differentiate",
    "cell_functions": "cell_gradient",
    "write_cell_gradient": "cell_gradient",
})
