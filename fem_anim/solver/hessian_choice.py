"""Which Hessian each Newton iteration uses: ``solver.hessian`` (seed section 3.2.2, note 4).

The remedies themselves (the shift's schedule, the per-point eigenvalue filters, the
trust-region ratio) are in :mod:`fem_anim.solver.hessian_modification`; :class:`HessianChoice`
is the state a :class:`~fem_anim.solver.minimiser.Minimiser` keeps across the iterations of
one step to apply them, as its SNES Jacobian callback (:meth:`HessianChoice.jacobian`):

* ``exact``, ``project`` (clamp), ``abs``: the problem's Hessian as assembled (the filter,
  if any, is fixed for the run);
* ``shift``: H + c I with c raised until the factorisation (or a CG probe,
  :func:`cg_probe`) shows no negative curvature, lowered after each success;
* ``trust_region_filter``: clamp or abs per iteration from the ratio rho of the previous
  step's actual to predicted decrease under the unprojected model;
* ``auto``: exact while the factorisation's inertia shows no negative pivot, else the
  trust-region filter's choice. With CG (Krylov presets) the iteration is truncated
  Newton-CG, in a trust region once the step meets indefiniteness
  (:mod:`fem_anim.solver.trust_region`); only when a direction fails too does
  :meth:`HessianChoice.restart` continue the step filtered from its last iterate.

Each step's iterations are counted per kind of Hessian (:data:`HESSIAN_KINDS`).
"""

from __future__ import annotations

from collections import Counter

from petsc4py import PETSc

from fem_anim.errors import ConvergenceError
from fem_anim.solver.hessian_modification import ShiftStrategy, model_ratio, trust_region_choice
from fem_anim.solver.trust_region import NewtonCGTrustRegion

__all__ = ["HessianChoice", "HESSIAN_KINDS", "FAILED_DIRECTION", "MAX_AUTO_RESTARTS",
           "cg_probe"]

#: The Hessians a Newton iteration may use (counted per step):
#: exact, exact + c I with c > 0, elastic tangent clamped, elastic tangent abs-filtered.
HESSIAN_KINDS = ("exact", "shift", "clamp", "abs")
#: SNES reasons of a solve whose last iteration computed a direction and then dropped it: its
#: linear solve failed (CG met negative curvature) or its line search did (no descent).
#: PETSc does not count that iteration (:class:`~fem_anim.solver.solve_stats.SolveStats`
#: does); after either, ``hessian = "auto"`` continues the step with the filtered Hessian.
FAILED_DIRECTION = (PETSc.SNES.ConvergedReason.DIVERGED_LINEAR_SOLVE,
                    PETSc.SNES.ConvergedReason.DIVERGED_LINE_SEARCH)
#: How often one step of ``auto`` may continue after such a failure.
MAX_AUTO_RESTARTS = 4


def cg_probe(A: PETSc.Mat, pc_type: str = "jacobi", rtol: float = 1e-6,
             max_it: int = 200) -> int:
    """The KSP reason of CG on A z = b for a random b (collective): ``DIVERGED_INDEFINITE_MAT``
    shows negative curvature of A (under an SPD preconditioner)."""
    probe = PETSc.KSP().create(A.getComm())
    probe.setOperators(A, A)
    probe.setType("cg")
    probe.getPC().setType(pc_type)
    probe.setTolerances(rtol=rtol, max_it=max_it)
    b, z = A.createVecs()
    b.setRandom()
    probe.solve(b, z)
    reason = probe.getConvergedReason()
    for obj in (probe, b, z):
        obj.destroy()
    return reason


class HessianChoice(NewtonCGTrustRegion):
    """The Hessian of each Newton iteration of one :class:`~fem_anim.solver.minimiser.Minimiser`.

    Args:
        mode: ``solver.hessian`` (:data:`fem_anim.solver.hessian_modification.MODES`).
        problem: The :class:`~fem_anim.problem.objective.EnergyProblem` (assembles the Hessian,
            sets the per-point filter, gives the unprojected curvature y^T H y).
        snes: The minimiser's SNES (its KSP factorises and probes the Hessian).
        objective: ``objective(snes, x)``, the minimiser's cached g.
        residual: The vector SNES keeps the residual at the current iterate in (r . y is
            the model's slope).
    """

    def __init__(self, mode: str, problem, snes: PETSc.SNES, objective,
                 residual: PETSc.Vec):
        self.mode = mode
        self.problem = problem
        self.snes = snes
        self._objective = objective
        self.problem_residual = residual
        self.shift = ShiftStrategy() if mode == "shift" else None
        self.its: Counter = Counter()  # this step's iterations per kind of Hessian
        self._model = None  # (x_k, y_k, g_k, r.y, y^T H y) of the last direction, for rho
        self._filtered = False  # auto: this step met an indefinite Hessian
        self._no_exact = False  # auto: ... shown by a failed Krylov solve or line search
        self.restarts = 0
        self.truncated = 0  # auto with CG: this step's solves stopped at negative curvature
        self._last_iterate = None
        self.inertia_checks = 0  # this step's Hessians whose factorisation gave the inertia
        self.inertia_fallbacks = 0  # ... that reported none: checked by cg_probe instead
        self._start_trust_region()  # auto with CG (NewtonCGTrustRegion)

    def start_step(self) -> None:
        """Forget the previous step: counts, model, auto's state."""
        self.its = Counter()
        self.drop_model()
        self._filtered = self._no_exact = False
        self.restarts = self.truncated = 0
        self.inertia_checks = self.inertia_fallbacks = 0
        self._indefinite_seen = False
        self.leave_trust_region()
        self._radius = None
        self._longest = 0.0

    def solved(self) -> int:
        """After each SNES solve: count the truncated CG directions it took (``auto``);
        returns the CG iterations of the descent directions it solved for
        (:meth:`descent_direction`), which SNES does not count."""
        if self._truncated:
            self.truncated += self.snes.getLinearSolveFailures()
        extra, self._extra_linear_its = self._extra_linear_its, 0
        return extra

    def restart(self, reason: int, stalled: bool, x: PETSc.Vec) -> bool:
        """Whether ``auto`` continues a failed SNES solve filtered; if so x is reset.

        After CG's negative curvature or a failed line search (not at the objective's
        round-off, ``stalled``, unless the direction was a truncated CG iterate), at most
        :data:`MAX_AUTO_RESTARTS` times per step, the step goes on from its last iterate
        with the trust-region filter's Hessian.
        """
        # a line search stalled on a truncated CG direction is that direction's fault, not
        # the round-off floor's
        truncated = bool(self._truncated) and \
            self.snes.getKSP().getConvergedReason() < 0
        if self.mode != "auto" or reason not in FAILED_DIRECTION or (stalled and not truncated) \
                or self.restarts >= MAX_AUTO_RESTARTS or self._last_iterate is None:
            return False
        self.restarts += 1
        self._filtered = self._no_exact = True
        self.drop_model()
        self._last_iterate.copy(x)
        return True

    def end_step(self) -> None:
        """``auto``: the next step starts exact, with plain CG."""
        if self.mode == "auto":
            self.problem.set_hessian_filter(None)
            self.leave_trust_region()

    def count_polish(self, steps: int) -> None:
        """Count the round-off polish's full Newton steps
        (:func:`fem_anim.solver.stopping.polish`, after :meth:`end_step`) under the Hessian the
        problem then assembles: exact, or the filter in place (``project``, ``abs``;
        ``trust_region_filter``'s last choice).
        """
        self.its[self.problem.hessian_filter or "exact"] += steps

    def counts(self) -> dict[str, int]:
        """This step's Newton iterations per kind of Hessian."""
        return {kind: self.its[kind] for kind in HESSIAN_KINDS}

    def record_model(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """Keep the exact quadratic model of g at x along y for the next iteration's rho.

        Needed by the trust-region filter, and by ``auto`` once a step has switched to
        the filtered Hessian: g(x), r.y and y^T H y with H unprojected
        (:meth:`fem_anim.problem.objective.EnergyProblem.curvature`).
        """
        length = y.norm() if self._truncated else None
        if length is not None:
            self._longest = max(self._longest, length)
        if not (self.mode == "trust_region_filter" or self._radius is not None or
                (self.mode == "auto" and self._filtered)):
            self.drop_model()
            return
        g = self._objective(self.snes, x)
        slope = self.problem_residual.dot(y)
        curvature = self._stcg_curvature(length, slope) if self._radius is not None else None
        if curvature is None:
            curvature = self.problem.curvature(x, y)
        if self._model is None:
            self._model = [x.copy(), y.copy(), g, slope, curvature]
        else:
            x.copy(self._model[0])
            y.copy(self._model[1])
            self._model[2:] = [g, slope, curvature]

    def drop_model(self) -> None:
        if self._model is not None:
            self._model[0].destroy()
            self._model[1].destroy()
        self._model = None

    def _model_ratio(self, x: PETSc.Vec) -> float | None:
        """rho of the step that led to x from the recorded model (None without one)."""
        if self._model is None:
            return None
        x_k, y, g_k, slope, curvature = self._model
        p = x.duplicate()
        x.copy(p)
        p.axpy(-1.0, x_k)  # p = x_{k+1} - x_k = -alpha y
        yy = y.dot(y)
        alpha = -p.dot(y) / yy if yy > 0.0 else 0.0
        p.destroy()
        self.drop_model()
        self._step_taken = (alpha, yy ** 0.5)
        return model_ratio(g_k - self._objective(self.snes, x), slope, curvature, alpha)

    def jacobian(self, snes, x: PETSc.Vec, A: PETSc.Mat, P: PETSc.Mat) -> None:
        """The problem's Hessian, shifted by c I until it is positive definite if asked.

        Positive definiteness is read off the factorisation: the inertia of MUMPS's or
        PETSc's Cholesky (negative pivots), or a PETSc factorisation failure; for a
        Krylov preset CG is run on the shifted matrix and must not meet negative
        curvature. c starts from the last successful shift, quartered
        (:class:`~fem_anim.solver.hessian_modification.ShiftStrategy`).

        Args:
            snes: The minimiser's SNES.
            x: The iterate.
            A: The matrix assembled into (and shifted).
            P: Its preconditioning matrix (the same).

        Raises:
            ConvergenceError: if the shift grows beyond 1e12 times the diagonal.
        """
        if self.mode in ("trust_region_filter", "auto"):
            self._filtered_jacobian(snes, x, A, P)
            return
        self.problem.jacobian(snes, x, A, P)
        if self.shift is None:
            self.its[{"project": "clamp", "abs": "abs"}.get(self.mode, "exact")] += 1
            return
        scale = A.getDiagonal().norm(PETSc.NormType.INFINITY)
        c = self.shift.first(scale)
        if c > 0.0:
            A.shift(c)
        while not self._positive_definite(A):
            previous = c
            c = self.shift.raise_shift(scale)
            A.shift(c - previous)
            if c > 1e12 * max(scale, 1.0):
                raise ConvergenceError("the Hessian shift grew beyond 1e12 x its diagonal: the "
                                       "linear solver never reported a positive definite matrix")
        self.its["shift" if c > 0.0 else "exact"] += 1
        self.shift.succeeded()

    def _filtered_jacobian(self, snes, x: PETSc.Vec, A: PETSc.Mat, P: PETSc.Mat) -> None:
        """The Hessian of ``trust_region_filter`` and ``auto`` (:mod:`fem_anim.solver.hessian_modification`).

        trust_region_filter: clamp if the exact model predicted the last step's decrease
        to 1 % (|rho - 1| < 0.01), else abs. auto: the exact Hessian whenever it is
        positive definite; else the trust-region filter's choice. With a Cholesky
        factorisation every iteration assembles the exact Hessian first and reads the
        inertia of its factorisation (kept for the solve when it has no negative pivot).
        With CG an indefinite Hessian gives a truncated direction (:meth:`_truncate_cg`);
        other Krylov methods, and a truncated direction that fails the line search, show
        it by a failed SNES solve, after which the step continues filtered: abs, or exact again
        where the trust-region filter would clamp (the exact model is accurate there;
        should CG fail again, the step continues filtered, at most
        :data:`MAX_AUTO_RESTARTS` times).
        """
        rho = self._model_ratio(x)
        problem = self.problem
        if self.mode == "auto" and self._truncated is None:
            self._truncate_cg()
        if self.mode == "trust_region_filter":
            how = trust_region_choice(rho)
        else:
            if self._last_iterate is None:
                self._last_iterate = x.duplicate()
            x.copy(self._last_iterate)
            how = trust_region_choice(rho) if self._no_exact else None
            if how == "clamp" and self.restarts < MAX_AUTO_RESTARTS:
                how = None
        problem.set_hessian_filter(how)
        problem.jacobian(snes, x, A, P)
        if self.mode == "auto" and how is None and self._negative_pivots(A):
            self._filtered = True
            how = trust_region_choice(rho)
            problem.set_hessian_filter(how)
            problem.jacobian(snes, x, A, P)
        if self._truncated:
            self._precondition(snes, x, A, how, self._cg_saw_indefinite(snes))
            if how is not None or self._indefinite_seen:
                self._trust_region(rho, A)
        self.its[how or "exact"] += 1

    def enable_inertia(self, A: PETSc.Mat) -> dict[str, str]:
        """Make MUMPS's Cholesky report the inertia of every factorisation (``auto``).

        The number of negative pivots is MUMPS's INFOG(12) (:meth:`_negative_count`); under
        MPI it counts the whole matrix only with ICNTL(13) = 1 (no ScaLAPACK on the root
        node, which reports no inertia). A control set on the factor matrix lasts only as
        long as that factor: PCSetUp destroys it and makes a new one, with MUMPS's defaults
        and the ``-mat_mumps_*`` options then in PETSc's database, whenever the Hessian's
        nonzero pattern changed (contact pairs add nonzeros, as soon as new pairs appear).
        So the control is set on the first factor and also
        returned as a solver option, to be in the database at every factorisation
        (:class:`~fem_anim.solver.minimiser.Minimiser` keeps it there while solving).

        Returns:
            The options (names without prefix) to keep in the database; empty for other
            solvers.
        """
        ksp = self.snes.getKSP()
        pc = ksp.getPC()
        if pc.getType() != "cholesky" or pc.getFactorSolverType() != "mumps":
            return {}
        ksp.setOperators(A, A)
        pc.setFactorSetUpSolverType()
        pc.getFactorMatrix().setMumpsIcntl(13, 1)  # the inertia of the whole matrix under MPI
        return {"mat_mumps_icntl_13": "1"}

    def _negative_count(self, pc: PETSc.PC) -> int | None:
        """The negative pivots of the factorisation of ``pc`` (set up), or None where it
        reports no inertia: MUMPS's Cholesky INFOG(12) (under MPI only with ICNTL(13) = 1;
        for an LU factorisation INFOG(12) counts off-diagonal pivots instead), others by
        MatGetInertia (PETSc's own Cholesky; an LU factorisation has none)."""
        factor = pc.getFactorMatrix()
        PETSc.Sys.pushErrorHandler("ignore")
        try:
            if pc.getType() == "cholesky" and pc.getFactorSolverType() == "mumps":
                if factor.getComm().getSize() > 1 and factor.getMumpsIcntl(13) != 1:
                    return None
                return int(factor.getMumpsInfog(12))
            negative, _, _ = factor.getInertia()
            return int(negative)
        except PETSc.Error:
            return None
        finally:
            PETSc.Sys.popErrorHandler()

    def _negative_pivots(self, A: PETSc.Mat) -> bool:
        """Whether the exact Hessian A is indefinite (``auto``; the factorisation is kept for
        the solve).

        With a Cholesky preset, from the inertia of its factorisation (counted in
        ``inertia_checks``); should the factorisation report none, by the eigenvalue-free
        :func:`cg_probe` instead, counted in ``inertia_fallbacks`` (stats.csv), so the check
        is never lost silently. False for solvers that report no inertia (Krylov presets,
        LU): ``auto`` then learns of an indefinite Hessian from the failed solve or line
        search instead.
        """
        ksp = self.snes.getKSP()
        pc = ksp.getPC()
        if pc.getType() != "cholesky":
            return False
        ksp.setOperators(A, A)
        PETSc.Sys.pushErrorHandler("ignore")
        try:
            pc.setUp()
            negative = self._negative_count(pc)
        except PETSc.Error:
            negative = None  # e.g. PETSc's Cholesky stopped at a zero pivot
        finally:
            PETSc.Sys.popErrorHandler()
        if negative is None:
            self.inertia_fallbacks += 1
            return cg_probe(A) == PETSc.KSP.ConvergedReason.DIVERGED_INDEFINITE_MAT
        self.inertia_checks += 1
        return negative > 0

    def _positive_definite(self, A: PETSc.Mat) -> bool:
        ksp = self.snes.getKSP()
        ksp.setOperators(A, A)
        pc = ksp.getPC()
        if pc.getType() in ("cholesky", "lu"):
            PETSc.Sys.pushErrorHandler("ignore")
            try:
                pc.setUp()
                negative = self._negative_count(pc)
            except PETSc.Error:
                negative = None  # this factorisation reports no inertia: ask CG instead
            finally:
                PETSc.Sys.popErrorHandler()
            if negative is not None:
                self.inertia_checks += 1
                return negative == 0
            self.inertia_fallbacks += 1
        return cg_probe(A) != PETSc.KSP.ConvergedReason.DIVERGED_INDEFINITE_MAT

    def destroy(self) -> None:
        """Free the matrices and vectors kept across steps."""
        self._destroy_trust_region()
        if self._last_iterate is not None:
            self._last_iterate.destroy()
        self.drop_model()
