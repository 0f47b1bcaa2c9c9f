"""What one minimisation of the step objective cost and how it ended (seed section 3.2)."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["SolveStats"]


@dataclass
class SolveStats:
    """The record of one :meth:`fem_anim.solver.minimiser.Minimiser.solve`.

    Attributes:
        newton_its: Every Newton iteration: every direction computed, those whose line
            search or linear solve failed (which PETSc leaves out) and the round-off
            polish's full steps included.
        linear_its: Every linear iteration of the step's solves (SNES's, the
            descent-direction replacements', the round-off check's and the polish's).
        reason: The SNES reason reported (:mod:`fem_anim.solver.stopping`:
            :data:`~fem_anim.solver.stopping.POLISH_FAILED_REASON` for a step kept at the
            round-off floor without meeting its test,
            :data:`~fem_anim.solver.stopping.BUDGET_REASON` for one accepted at its budget).
        residual_norm: ||r|| at the minimiser.
        wall_s: Wall seconds of the solve.
        newton_decrement: lambda^2/2 at the last Newton direction (seed definition 4; NaN
            for methods without one, and for a saddle point).
        shift: The last Hessian shift c (``solver.hessian = "shift"``), else 0.
        assembly_s: Wall seconds spent assembling.
        factor_s: Wall seconds in preconditioner set-ups (PCSetUp: factorisations).
        linear_solve_s: Wall seconds in linear solves (KSPSolve).
        initial_residual_norm: r0, the residual norm at the initial guess (the relative
            test is ``residual_norm <= snes_rtol r0``).
        hessian_its: The same iterations per kind of Hessian
            (:data:`fem_anim.solver.hessian_choice.HESSIAN_KINDS`; they sum to
            ``newton_its`` when the Hessian is assembled at every iteration).
        residual_ratio: ``residual_norm / max(snes_atol, snes_rtol r0)``: <= 1 where the
            norm test is met, its excess for a step accepted at its budget.
        hessian_assemblies: Hessians assembled (fewer than the iterations when
            ``solver.hessian_update`` keeps one).
        factorisations: Preconditioner set-ups (PETSc's PCSetUp events: a direct solver's
            factorisations).
        inertia_checks: Hessians whose definiteness ``solver.hessian = "auto"`` or
            ``"shift"`` read off the inertia of their Cholesky factorisation.
        inertia_fallbacks: ... whose factorisation reported no inertia, so the CG probe
            (:func:`fem_anim.solver.hessian_choice.cg_probe`) judged them instead.
    """

    newton_its: int
    linear_its: int
    reason: int
    residual_norm: float
    wall_s: float
    newton_decrement: float = float("nan")
    shift: float = 0.0
    assembly_s: float = 0.0
    factor_s: float = 0.0
    linear_solve_s: float = 0.0
    initial_residual_norm: float = float("nan")
    hessian_its: dict = field(default_factory=dict)
    residual_ratio: float = float("nan")
    hessian_assemblies: int = 0
    factorisations: int = 0
    inertia_checks: int = 0
    inertia_fallbacks: int = 0
