"""How often Newton's Hessian is rebuilt: ``solver.hessian_update`` (seed eq. 10).

Each Newton iteration solves H d = r (seed eq. 10). Any symmetric positive definite H
gives a descent direction of the step objective g (r . d = r^T H^-1 r > 0), so the line
search on g still decreases it and the same residual test still ends the step; only the
rate changes (quadratic with the exact H, linear with a fixed one). A Hessian kept for
several iterations saves its assembly and, with a direct solver, its factorisation:

* ``every_iteration``: the exact Newton of seed eq. 10 (the default);
* ``every_step``: assembled and factored at the first iteration of each step (a chord
  method per step);
* ``lagged``: rebuilt every ``solver.hessian_lag`` iterations, counted across steps;
* ``rest``: M + w K(X), the Hessian of the same step objective at the rest state,
  assembled and factored once per run and again when w (dt) changes: the
  Projective-Dynamics-like end (constant matrix, one factorisation). It is SPD where the
  material is stable at rest. With ``solver.method = "lbfgs"`` it is L-BFGS's initial
  Hessian (Liu, Bouaziz and Kavan 2017; PETSc's ``-snes_qn_scale_type jacobian``).

The refactor rule of ``every_step`` and ``lagged``: a stale Hessian whose Newton step the
line search had to shorten is rebuilt at the next iteration, and a step whose line search
failed with a stale Hessian continues once from its last iterate with a fresh one
(:meth:`HessianReuse.retry`). The time step's weight w changing (adaptive dt) rebuilds
every kept Hessian: it is the Hessian of another objective.

The reuse itself is PETSc's: the Jacobian callback leaves the matrix untouched, so its
object state does not change and ``PCSetUp`` keeps the factorisation (or ICC, AMG, ...)
as it is ("operator is unchanged"). petsc4py 3.18 has no ``SNESSetLagJacobian``, which
the rule would need at run time; PETSc's own ``-snes_lag_jacobian N
-snes_lag_jacobian_persists`` still work from the command line (a fixed lag, no rule).
"""

from __future__ import annotations

from petsc4py import PETSc

from fem_anim.scene.schema import HESSIAN_UPDATES

__all__ = ["HessianReuse", "HESSIAN_UPDATES"]
#: A line-search factor below this shortened the Newton step (the rule rebuilds H).
FULL_STEP = 1.0 - 1e-10


class HessianReuse:
    """Decides, iteration by iteration, whether the Hessian callback assembles.

    Args:
        mode: ``solver.hessian_update`` (:data:`HESSIAN_UPDATES`).
        lag: ``solver.hessian_lag``: iterations a ``lagged`` Hessian is kept.
        problem: The :class:`~fem_anim.problem.objective.EnergyProblem` (its ``weight`` w).
        assemble: ``assemble(snes, x, A, P)``, the Hessian of the iteration
            (:meth:`fem_anim.solver.hessian_choice.HessianChoice.jacobian`).
    """

    def __init__(self, mode: str, lag: int, problem, assemble):
        self.mode = mode
        self.lag = lag
        self.problem = problem
        self._assemble = assemble
        self._force = True  # the next callback assembles
        self._age = 0  # iterations the current Hessian has served
        self._weight = None
        self._rest = None  # the rest state (zero displacement), for "rest"
        self._x = self._y = None  # the last iterate and its direction (the rule)
        self._exact = None  # rest: (KSP, matrix) for exact Hessians (exact_solver)
        self._retried = False
        self._stale = False  # the last direction came from a kept Hessian
        self.assemblies = self.reused = 0  # this step's

    @property
    def active(self) -> bool:
        return self.mode != "every_iteration"

    def start_step(self) -> None:
        """A new step: ``every_step`` rebuilds, any mode rebuilds when w changed."""
        weight = float(self.problem.weight.value)
        # a frame's last substep lands on the frame time: dt (and w) differ in round-off
        changed = self._weight is None or abs(weight - self._weight) > 1e-9 * abs(self._weight)
        if self.mode == "every_step" or changed:
            self._force = True
        self._weight = weight
        self._retried = False
        self.assemblies = self.reused = 0

    def exact_solver(self, snes: PETSc.SNES, mat_type: str | None, options: dict,
                     prefix: str) -> tuple[PETSc.KSP, PETSc.Mat] | None:
        """``rest``: a matrix and linear solver of its own (the same PETSc options) for the
        exact Hessians others assemble (the round-off polish, a start from the linearised
        response), so the run's one factorisation of M + w K(X) is not overwritten; None
        for the other modes, whose kept Hessian those simply replace (:meth:`invalidate`)."""
        if self.mode != "rest":
            return None
        if self._exact is None:
            from fem_anim.petsc_options import options_in_database

            A = self.problem.create_matrix(mat_type)
            ksp = PETSc.KSP().create(snes.getComm())
            ksp.setOptionsPrefix(prefix)
            with options_in_database(prefix, options):
                ksp.setFromOptions()
            self._exact = (ksp, A)
        return self._exact

    def invalidate(self) -> None:
        """Another Hessian was assembled into the matrix (the polish, a start): rebuild."""
        self._force = True

    def jacobian(self, snes, x: PETSc.Vec, A: PETSc.Mat, P: PETSc.Mat) -> None:
        """The SNES Jacobian callback: assemble, or leave A (and its factors) as they are."""
        stale = self.mode == "every_step" or \
            (self.mode == "lagged" and self._age < self.lag) or self.mode == "rest"
        if not self.active or self._force or not stale:
            self._force = False
            self._age = 0
            self.assemblies += 1
            if self.mode == "rest":
                if self._rest is None:
                    self._rest = x.duplicate()
                self._rest.zeroEntries()  # u = 0: the rest state; pinned rows are identity
                self._assemble(snes, self._rest, A, P)
            else:
                self._assemble(snes, x, A, P)
        else:
            self.reused += 1
        self._stale = self._age > 0
        self._age += 1

    def record_direction(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """Keep x_k and the searched direction y_k (x_{k+1} = x_k - alpha y_k)."""
        if self.mode not in ("every_step", "lagged"):
            return
        if self._x is None:
            self._x, self._y = x.duplicate(), y.duplicate()
        x.copy(self._x)
        y.copy(self._y)

    def check_step(self, x: PETSc.Vec) -> None:
        """After the line search: a shortened step (alpha < 1) rebuilds the Hessian."""
        if self._x is None or self.mode not in ("every_step", "lagged"):
            return
        d = self._x.copy()
        d.axpy(-1.0, x)  # alpha y
        yy = self._y.dot(self._y)
        alpha = d.dot(self._y) / yy if yy > 0.0 else 1.0
        d.destroy()
        if alpha < FULL_STEP and self._stale:
            self._force = True

    def retry(self, reason: int, x: PETSc.Vec) -> bool:
        """Whether a step whose line search failed on a kept Hessian continues (once per
        step) with a fresh one from its last iterate (copied into x)."""
        if reason != PETSc.SNES.ConvergedReason.DIVERGED_LINE_SEARCH or self._retried or \
                self.mode not in ("every_step", "lagged") or self._x is None or \
                not self._stale:
            return False
        self._retried = True
        self._force = True
        self._x.copy(x)
        return True

    def destroy(self) -> None:
        for v in (self._rest, self._x, self._y) + (self._exact or ()):
            if v is not None:
                v.destroy()
