"""Newton-CG in a trust region: ``solver.hessian = "auto"`` with CG (seed section 3.2.2).

With a Krylov preset ``auto`` cannot read the Hessian's inertia from a factorisation, so it
runs truncated Newton-CG (Steihaug 1983; Nocedal & Wright, Algorithms 7.1 and 7.2):

* CG stopped by negative curvature (``DIVERGED_INDEFINITE_MAT``) leaves its last iterate, a
  descent direction, and SNES takes it (:meth:`NewtonCGTrustRegion._truncate_cg`);
* an ascent direction (negative curvature at CG's first direction) is replaced by the
  abs-filtered Newton direction (:meth:`NewtonCGTrustRegion.descent_direction`);
* once a step has shown CG indefiniteness, CG is preconditioned by shifted incomplete
  Cholesky of an AIJ copy of A, positive definite (:meth:`NewtonCGTrustRegion._precondition`),
  and the rest of the step is Newton-CG in a trust region by KSPSTCG, whose radius follows
  the exact model's ratio rho (:meth:`NewtonCGTrustRegion._trust_region`).

KSPSTCG's controls ``KSPCGSetRadius``, ``KSPCGGetNormD`` and ``KSPCGGetObjFcn`` exist under
these names in PETSc 3.18 and 3.22 but not in their petsc4py: :func:`set_radius`,
:func:`direction_norm` and :func:`model_value` call them through ctypes in the PETSc library
petsc4py links, with the KSP's handle. The radius bounds the Euclidean norm ||d||_2 of the
direction in both versions (tests/test_ksp_trust_region.py).
"""

from __future__ import annotations

import ctypes
import functools

from petsc4py import PETSc

from fem_anim.solver.hessian_modification import trust_radius

__all__ = ["NewtonCGTrustRegion", "direction_norm", "model_value", "set_radius"]


@functools.lru_cache(maxsize=1)
def _library() -> ctypes.CDLL:
    """petsc4py's extension module, whose symbol look-up (``dlsym``) also searches the
    libraries it links, PETSc's among them: the PETSc petsc4py uses, whatever its path."""
    library = ctypes.CDLL(PETSc.__file__)
    library.KSPCGSetRadius.argtypes = [ctypes.c_void_p, ctypes.c_double]
    for name in ("KSPCGGetNormD", "KSPCGGetObjFcn"):
        getattr(library, name).argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)]
    return library


def _check(code: int) -> None:
    if code != 0:
        raise PETSc.Error(code)


def set_radius(ksp: PETSc.KSP, radius: float) -> None:
    """Set the trust-region radius of a KSPSTCG (logically collective: the same on all ranks).

    Raises:
        PETSc.Error: if PETSc returns an error code.
    """
    _check(_library().KSPCGSetRadius(ctypes.c_void_p(ksp.handle), float(radius)))


def _get(name: str, ksp: PETSc.KSP) -> float:
    value = ctypes.c_double()
    _check(getattr(_library(), name)(ctypes.c_void_p(ksp.handle), ctypes.byref(value)))
    return value.value


def direction_norm(ksp: PETSc.KSP) -> float:
    """||d||_2 of a KSPSTCG's last solve's direction d.

    Raises:
        PETSc.Error: if PETSc returns an error code.
    """
    return _get("KSPCGGetNormD", ksp)


def model_value(ksp: PETSc.KSP) -> float:
    """A KSPSTCG's last solve's quadratic model at its direction: 1/2 d^T A d - b^T d.

    Raises:
        PETSc.Error: if PETSc returns an error code.
    """
    return _get("KSPCGGetObjFcn", ksp)


class NewtonCGTrustRegion:
    """The Newton-CG trust-region part of :class:`~fem_anim.solver.hessian_choice.HessianChoice`.

    A base class holding the state ``auto`` with CG keeps across one step's iterations; the
    subclass provides ``snes``, ``problem``, ``problem_residual`` (r at the iterate),
    ``its`` (the step's iterations per kind of Hessian) and ``restarts``, and calls
    :meth:`_start_trust_region` from its ``__init__``.
    """

    def _start_trust_region(self) -> None:
        """The state of a minimiser that has not solved yet."""
        self._truncated = None  # whether CG's truncated iterates are taken (first use)
        self._indefinite_seen = False  # CG met indefiniteness in this step
        self._pc_matrix = None  # the AIJ matrix CG is preconditioned by
        self._abs_matrix = None  # the abs-filtered Hessian of descent_direction
        self.aij_preconditioners = 0  # iterations preconditioned by it (the whole run)
        self.descent_solves = 0  # ascent directions of CG replaced (the whole run)
        self._extra_linear_its = 0  # CG iterations of those replacements, this SNES solve
        self._radius = None  # the trust radius once the step met indefiniteness
        self._in_region = False  # the KSP was switched to KSPSTCG by _trust_region
        self._longest = 0.0  # the longest Newton direction of the step so far (its start)
        self._step_taken = None  # (alpha, ||y||) of the step the last model ratio judged
        self.trust_region_its = 0  # iterations solved by KSPSTCG in a trust region (the run)

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

    def _cg_saw_indefinite(self, snes) -> bool:
        """Whether CG met an indefinite matrix or preconditioner earlier in this step (the
        last solve's KSP reason, read from the step's second iteration or a restart on)."""
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
        iteration: a current preconditioner.

        Args:
            snes: The minimiser's SNES (its Jacobian's preconditioning matrix is set).
            x: The iterate.
            A: The Hessian just assembled.
            how: The filter of this iteration's Hessian (None: exact).
            seen: Whether CG met indefiniteness earlier in the step.
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
        directions overshoot. KSPSTCG follows negative curvature to the boundary of a trust
        region ||d|| <= Delta (Euclidean in PETSc 3.18 and 3.22) and stops there when CG's
        iterate leaves it, so the direction's length is the model's reach rather than the
        Newton step's. Delta starts at the length of the step's longest Newton direction so
        far (its first, from the initial guess: the scale of the step's motion; a step bound
        or the line search cuts it at once; before any, :meth:`_jacobi_length`) and then follows
        :func:`fem_anim.solver.hessian_modification.trust_radius` (rho of the exact model,
        whose curvature y^T A y comes from KSPSTCG's model value: no assembly). The line search on g still
        decides the step's length, and the stopping test is unchanged. The preconditioner
        is positive definite, as KSPSTCG requires (:meth:`_precondition`).

        Args:
            rho: The model ratio of the step that led here (None without one).
            A: The Hessian (its diagonal gives a first radius without a Newton direction).
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
        set_radius(ksp, self._radius)
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
        norm_d = direction_norm(ksp)
        if not norm_d > 0.0:
            return None
        t = length / norm_d  # y = t d (a step bound may have scaled it)
        return 2.0 * t * t * (model_value(ksp) + slope / t)

    def leave_trust_region(self) -> None:
        """Plain CG again (the step ended, or a full Newton step is wanted), if
        :meth:`_trust_region` made it KSPSTCG (a KSPSTCG of the user's options stays)."""
        if self._in_region:
            self.snes.getKSP().setType("cg")
            self._in_region = False

    def _aij_matrix(self) -> PETSc.Mat:
        """The AIJ preconditioning matrix (made at its first use), the target of
        ``MatConvert``: assembling into it is not safe (on several ranks the converted
        matrix keeps only the nonzeros it was converted from: a form's new nonzero is a
        PETSc error)."""
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
        abs-filtered Newton direction (solves ``(M + w K_abs) y = r``); whether y was replaced.

        PETSc's KSPCG (3.18 to 3.22) declares ``DIVERGED_INDEFINITE_MAT`` on a *change of
        sign* of p^T A p between two directions: when the first direction already has
        negative curvature it steps along it with a negative length and stops one
        direction later, so its iterate is an ascent direction (r . y < 0: the line search
        then fails down to lambda = 1e-12). The filtered system is positive definite, so
        its solution is a descent direction. Called before the line search
        (:meth:`fem_anim.solver.minimiser.Minimiser._precheck`); the iteration counts as
        ``abs``.

        Args:
            x: The iterate.
            y: The direction of the last linear solve, replaced in place.
            r: The residual at x.

        Returns:
            Whether y was replaced.
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

    def _destroy_trust_region(self) -> None:
        for matrix in (self._pc_matrix, self._abs_matrix):
            if matrix is not None:
                matrix.destroy()
