"""Which Hessian each Newton iteration uses: ``solver.hessian`` (seed section 3.2.2, note 4).

The remedies themselves (the shift's schedule, the per-point eigenvalue filters, the
trust-region ratio) are in :mod:`fem_anim.solver.hessian_modification`; this module is the state a
:class:`~fem_anim.solver.minimiser.Minimiser` keeps across the iterations of one step to apply them:

* ``exact``, ``project`` (clamp), ``abs``: the problem's Hessian as assembled (the filter,
  if any, is fixed for the run);
* ``shift``: H + c I with c raised until the factorisation (or a CG probe) shows no
  negative curvature, lowered after each success (:class:`~fem_anim.solver.hessian_modification.ShiftStrategy`);
* ``trust_region_filter``: clamp or abs per iteration from the ratio rho of the previous
  step's actual to predicted decrease under the unprojected model;
* ``auto``: exact while the factorisation's inertia shows no negative pivot, else the
  trust-region filter's choice; with CG (Krylov presets) the iteration is truncated Newton-CG
  (Steihaug 1983; Nocedal & Wright, Algorithm 7.1): CG stopped by negative curvature
  (``DIVERGED_INDEFINITE_MAT``) leaves its last iterate, a descent direction, and SNES takes
  it (``SNESSetMaxLinearSolveFailures``); an ascent direction (negative curvature at CG's
  first direction) is replaced by the abs-filtered Newton direction; once a step has shown CG
  indefiniteness, the rest of the step is Newton-CG in a trust region (KSPSTCG, which follows
  negative curvature to the region's boundary; the radius follows the exact model's ratio
  rho), preconditioned by shifted incomplete Cholesky of A (positive definite); only when a
  direction fails too (zero after a first negative curvature, or the line search fails) does
  :meth:`HessianChoice.restart` continue the step filtered from its last iterate.

Each step's iterations are counted per kind of Hessian (:data:`HESSIAN_KINDS`).
"""

from __future__ import annotations

from collections import Counter

from petsc4py import PETSc

from fem_anim.solver import trust_region as ksp_trust_region
from fem_anim.errors import ConvergenceError
from fem_anim.solver.hessian_modification import ShiftStrategy, model_ratio, trust_radius, trust_region_choice

__all__ = ["HessianChoice", "HESSIAN_KINDS", "FAILED_DIRECTION", "MAX_AUTO_RESTARTS",
           "cg_probe"]

#: The Hessians a Newton iteration may use (counted per step):
#: exact, exact + c I with c > 0, elastic tangent clamped, elastic tangent abs-filtered.
HESSIAN_KINDS = ("exact", "shift", "clamp", "abs")
#: SNES reasons of a solve whose last iteration computed a direction and then dropped it: its
#: linear solve failed (CG met negative curvature) or its line search did (no descent). PETSc
#: does not count that iteration (:class:`~fem_anim.solver.minimiser.SolveStats` does); after either,
#: ``hessian = "auto"`` continues the step with the filtered Hessian.
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


class HessianChoice:
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
        self._inertia = True  # whether the factorisation reports its inertia (auto)
        self._truncated = None  # auto: whether CG's truncated iterates are taken (first use)
        self._indefinite_seen = False  # auto with CG: CG met indefiniteness in this step
        self._pc_matrix = None  # auto with CG: the AIJ matrix CG is preconditioned by
        self._abs_matrix = None  # ... the abs-filtered Hessian of descent_direction
        self.aij_preconditioners = 0  # iterations preconditioned by it (the whole run)
        self.descent_solves = 0  # ascent directions of CG replaced (the whole run)
        self._extra_linear_its = 0  # CG iterations of those replacements, this SNES solve
        self._radius = None  # auto with CG: the trust radius once the step met indefiniteness
        self._in_region = False  # ... the KSP was switched to KSPSTCG by _trust_region
        self._longest = 0.0  # ... the longest Newton direction of the step so far (its start)
        self._step_taken = None  # (alpha, ||y||) of the step the last model ratio judged
        self.trust_region_its = 0  # iterations solved by KSPSTCG in a trust region (the run)

    def start_step(self) -> None:
        """Forget the previous step: counts, model, auto's state."""
        self.its = Counter()
        self.drop_model()
        self._filtered = self._no_exact = False
        self.restarts = self.truncated = 0
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
        # a line search stalled on a truncated CG direction is that direction's fault
        # (measured: step 55 of the 55k beam kept at ||r|| / ||r_0|| = 0.1 by the polish)
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
        """Count the round-off polish's full Newton steps (:meth:`~fem_anim.solver.minimiser.Minimiser.
        _polish`, after :meth:`end_step`) under the Hessian the problem then assembles: exact,
        or the filter in place (``project``, ``abs``; ``trust_region_filter``'s last choice).
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
        curvature. c starts from the last successful shift, quartered (hessian.py).
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

    def _cg_saw_indefinite(self, snes) -> bool:
        """Whether CG met an indefinite matrix or preconditioner earlier in this step."""
        if snes.getIterationNumber() > 0 or self.restarts > 0:  # else: the last step's solve
            R = PETSc.KSP.ConvergedReason
            if snes.getKSP().getConvergedReason() in (R.DIVERGED_INDEFINITE_MAT,
                                                      R.DIVERGED_INDEFINITE_PC):
                self._indefinite_seen = True
        return self._indefinite_seen

    def _precondition(self, snes, x: PETSc.Vec, A: PETSc.Mat, how: str | None,
                      seen: bool) -> None:
        """``auto`` with CG: precondition by A itself or, once this step has shown CG an
        indefinite matrix or preconditioner (``seen``) or A is filtered (``how``), by
        incomplete Cholesky of an AIJ copy of A, which PETSc shifts to positive definite.

        Newton-CG in a trust region (:meth:`_trust_region`) needs a symmetric positive
        definite preconditioner (Nocedal & Wright, Algorithm 7.1; Steihaug 1983). PETSc's
        ICC of a 3 x 3-block (BAIJ) matrix applies no shift: on an indefinite Hessian CG
        stops after 2-3 iterations at ``DIVERGED_INDEFINITE_PC``, which is how a step first
        shows its indefiniteness. ICC of AIJ storage applies the Manteuffel shift
        (``POSITIVE_DEFINITE``, the default in PETSc 3.18 and 3.22): its factor L D L^T has
        D > 0, so the preconditioner is positive definite whatever A is, and CG still runs
        on the exact A. The copy (``MatConvert`` into a kept AIJ matrix) is made every
        iteration: a current preconditioner. Measured on frames 46-60 of the undamped ~55k
        beam (trust region on; one run each, load ~2): 6741 CG iterations and 24.0 s of
        stepping, against 8315 and 29.5 s when the preconditioner was the abs-filtered
        Hessian assembled once per step (an eigendecomposition per quadrature point, 0.43 s
        a step on 55k points, and a factor that grows stale within the step) and 15556 and
        33.6 s when that filtered Hessian was kept across steps.
        """
        J, current, (callback, args, kargs) = snes.getJacobian()
        filtered = how is not None or seen
        if filtered:
            A.convert("aij", self._aij_matrix())
            self.aij_preconditioners += 1
        wanted = self._pc_matrix if filtered else A
        if current.handle != wanted.handle:  # SNES passes (J, P) to the KSP after this call
            snes.setJacobian(callback, J, wanted, *(args or ()), **(kargs or {}))

    def _trust_region(self, rho: float | None, A: PETSc.Mat) -> None:
        """``auto`` with CG, once the step has met an indefinite Hessian: Newton-CG in a trust
        region (Steihaug 1983; Nocedal & Wright, Algorithms 4.1 and 7.2), by KSPSTCG.

        Truncated CG stops *before* a direction of negative curvature and hands the line
        search a Newton direction of the positive-curvature part: near a saddle of g such
        directions overshoot (the ~55k beam's frame 46: 12 of its 33 iterations took the
        backtracking's floor lambda = 0.1, 4 of them from CG's converged direction on an
        indefinite Hessian). KSPSTCG follows negative curvature to the boundary of a trust
        region ||d|| <= Delta (Euclidean in PETSc 3.18 and 3.22) and stops there when CG's
        iterate leaves it, so the direction's length is the model's reach rather than the
        Newton step's. Delta starts at the length of the step's longest Newton direction so
        far (its first, from the initial guess: the scale of the step's motion; a step bound
        or the line search cuts it at once; before any, :meth:`_jacobi_length`) and then follows
        :func:`fem_anim.solver.hessian_modification.trust_radius` (rho of the exact model, whose curvature
        y^T A y comes from KSPSTCG's model value: no assembly). The line search on g still
        decides the step's length, and the stopping test is unchanged. The preconditioner
        is positive definite, as KSPSTCG requires (:meth:`_precondition`).
        """
        ksp = self.snes.getKSP()
        if self._radius is None:
            self._radius = self._longest if self._longest > 0.0 else self._jacobi_length(A)
        elif rho is not None and self._step_taken is not None:
            self._radius = trust_radius(self._radius, rho, *self._step_taken)
        self._step_taken = None
        if not self._in_region:
            ksp.setType("stcg")
            self._in_region = True
        ksp_trust_region.set_radius(ksp, self._radius)
        self.trust_region_its += 1

    def _jacobi_length(self, A: PETSc.Mat) -> float:
        """||D^-1 r||, D = |diag A|: the length of the Jacobi step from the current iterate,
        the first trust radius of a step that has no Newton direction yet (a restart before
        any line search). Collective."""
        d = A.getDiagonal()
        d.abs()
        step = self.problem_residual.duplicate()
        step.pointwiseDivide(self.problem_residual, d)
        length = step.norm()
        d.destroy()
        step.destroy()
        return length

    def _stcg_curvature(self, length: float, slope: float) -> float | None:
        """y^T A y of the direction y (KSPSTCG's d, perhaps scaled since; ``length`` = ||y||,
        ``slope`` = r . y) from the solve's model value m(d) = 1/2 d^T A d - r . d: no
        assembly. None if the last solve was not KSPSTCG's in the trust region, failed, or
        gave a zero direction."""
        ksp = self.snes.getKSP()
        if not self._in_region or ksp.getConvergedReason() < 0:
            return None
        norm_d = ksp_trust_region.direction_norm(ksp)
        if not norm_d > 0.0:
            return None
        t = length / norm_d  # y = t d (a step bound may have scaled it)
        return 2.0 * t * t * (ksp_trust_region.model_value(ksp) + slope / t)

    def leave_trust_region(self) -> None:
        """Plain CG again (the step ended, or a full Newton step is wanted), if
        :meth:`_trust_region` made it KSPSTCG (a KSPSTCG of the user's options stays)."""
        if self._in_region:
            self.snes.getKSP().setType("cg")
            self._in_region = False

    def _aij_matrix(self) -> PETSc.Mat:
        """The AIJ preconditioning matrix (made at its first use), the target of
        ``MatConvert``: assembling into it is not safe (on several ranks the converted
        matrix keeps only the nonzeros it was converted from: a form's new nonzero is an
        error, measured on the 55k beam on 2 ranks)."""
        if self._pc_matrix is None:
            self._pc_matrix = self.problem.create_matrix("aij")
        return self._pc_matrix

    def _assemble_abs(self, snes, x: PETSc.Vec) -> PETSc.Mat:
        """The abs-filtered Hessian at x, assembled into a matrix of its own."""
        if self._abs_matrix is None:
            self._abs_matrix = self.problem.create_matrix("aij")
        self.problem.set_hessian_filter("abs")
        self.problem.jacobian(snes, x, self._abs_matrix, self._abs_matrix)
        self.problem.set_hessian_filter(None)
        return self._abs_matrix

    def descent_direction(self, x: PETSc.Vec, y: PETSc.Vec, r: PETSc.Vec) -> bool:
        """``auto`` with CG: replace an ascent direction y of a failed CG solve by the
        abs-filtered Newton direction (solves M + w K_|.| y = r); whether y was replaced.

        PETSc's KSPCG (3.18 to 3.22) declares ``DIVERGED_INDEFINITE_MAT`` on a *change of
        sign* of p^T A p between two directions: when the first direction already has
        negative curvature it steps along it with a negative length and stops one
        direction later, so its iterate is an ascent direction (r . y < 0: the line search
        then fails down to lambda = 1e-12; seen on the crushed stable neo-Hookean cube,
        where auto with ``cg-icc`` stopped at step 3). The filtered system is positive
        definite, so its solution is a descent direction. Called before the line search
        (:meth:`fem_anim.solver.minimiser.Minimiser._precheck`); the iteration counts as ``abs``.
        """
        ksp = self.snes.getKSP()
        if not self._truncated or ksp.getConvergedReason() >= 0 or r.dot(y) > 0.0:
            return False
        M = self._assemble_abs(self.snes, x)
        self._indefinite_seen = True
        ksp.setOperators(M, M)  # SNES sets its own again next
        y.zeroEntries()
        ksp.solve(r, y)
        self._extra_linear_its += ksp.getIterationNumber()
        self.descent_solves += 1
        self.its["exact"] -= 1
        self.its["abs"] += 1
        return True

    def _truncate_cg(self) -> None:
        """``auto`` with CG: Newton takes CG's iterate when CG meets negative curvature.

        PETSc's KSPCG (3.18 and 3.22) stops at p^T H p <= 0 before updating x, so x holds the
        last iterate x_j = sum_i a_i p_i of conjugate directions with positive curvature,
        started from 0: r^T x_j < 0, a descent direction for g (Nocedal & Wright, Theorem
        7.2 with a symmetric positive definite preconditioner). SNES counts such a solve
        as a failure and stops at ``snes_max_linear_solve_fail`` of them (default 1):
        raising the limit makes it take the iterate; the line search on g and the stopping
        test of every accepted step are unchanged. A zero iterate (negative curvature at
        CG's first direction) fails the line search and :meth:`restart` takes over.
        """
        self._truncated = self.snes.getKSP().getType() == "cg"
        if self._truncated:
            self.snes.setMaxLinearSolveFailures(1 << 30)

    def enable_inertia(self, A: PETSc.Mat) -> None:
        """Ask MUMPS's Cholesky for the inertia of its factors (``auto``).

        PETSc 3.18's MatGetInertia for MUMPS answers only with null-pivot detection
        (ICNTL(24) = 1), and MUMPS reads its ``-mat_mumps_*`` options when it first
        factorises, after the solver options have left PETSc's database
        (:func:`fem_anim.petsc_options.options_in_database`): the controls are set on
        the factor matrix itself, before its first factorisation.
        """
        ksp = self.snes.getKSP()
        pc = ksp.getPC()
        if pc.getType() != "cholesky" or pc.getFactorSolverType() != "mumps":
            return
        ksp.setOperators(A, A)
        pc.setFactorSetUpSolverType()
        factor = pc.getFactorMatrix()
        factor.setMumpsIcntl(24, 1)  # null pivot detection: MatGetInertia answers
        factor.setMumpsIcntl(13, 1)  # the inertia of the whole matrix under MPI

    def _negative_pivots(self, A: PETSc.Mat) -> bool:
        """Whether the Cholesky factorisation of A (kept for the solve) has a negative pivot.

        False for solvers that report no inertia (Krylov presets, LU): ``auto`` then learns
        of an indefinite Hessian from the failed solve or line search instead.
        """
        ksp = self.snes.getKSP()
        pc = ksp.getPC()
        if not self._inertia or pc.getType() != "cholesky":
            return False
        ksp.setOperators(A, A)
        PETSc.Sys.pushErrorHandler("ignore")
        try:
            pc.setUp()
            negative, _, _ = pc.getFactorMatrix().getInertia()
        except PETSc.Error:
            self._inertia = False  # this factorisation reports no inertia
            return False
        finally:
            PETSc.Sys.popErrorHandler()
        return negative > 0

    def _positive_definite(self, A: PETSc.Mat) -> bool:
        ksp = self.snes.getKSP()
        ksp.setOperators(A, A)
        pc = ksp.getPC()
        if pc.getType() in ("cholesky", "lu"):
            PETSc.Sys.pushErrorHandler("ignore")
            try:
                pc.setUp()
                negative, _, _ = pc.getFactorMatrix().getInertia()
                return negative == 0
            except PETSc.Error:
                pass  # this factorisation reports no inertia: ask CG instead
            finally:
                PETSc.Sys.popErrorHandler()
        return cg_probe(A) != PETSc.KSP.ConvergedReason.DIVERGED_INDEFINITE_MAT

    def destroy(self) -> None:
        for matrix in (self._pc_matrix, self._abs_matrix):
            if matrix is not None:
                matrix.destroy()
        if self._last_iterate is not None:
            self._last_iterate.destroy()
        self.drop_model()
