"""J(theta) of a simulated motion and its gradient: forward run, then the backward sweep.

:class:`AdjointModel` builds a scene's :class:`~fem_anim.simulation.loop.Simulation` once,
with its parameters bound (:mod:`fem_anim.adjoint.parameters`) and the adjoint's forms
compiled (:mod:`fem_anim.adjoint.backward`); :meth:`AdjointModel.evaluate` then runs the
forward steps at a parameter vector theta (each step the minimisation of seed eq. 4,
converged tightly: the derivative of a step holds at its stationary point only), keeps the
states (:mod:`fem_anim.adjoint.tape`), evaluates the objective
(:mod:`fem_anim.adjoint.objectives`) and sweeps back for dJ/dtheta. :func:`gradient` is the
one-call form at the scene's own values.

What is differentiated (the parameters: :mod:`fem_anim.adjoint.parameters`): implicit
Euler, BDF2 and Newmark; the displacement formulation with
materials whose energy is a UFL form of F (neo-Hookean, St. Venant-Kirchhoff, ...), per
region and per body; gravity, Rayleigh damping, pins and moving handles; with implicit
Euler and BDF2 also obstacles and IPC contact, barrier and lagged friction, exactly
(:mod:`fem_anim.adjoint.backward`; kappa and d_hat held fixed). Refused with one line (a
:class:`~fem_anim.errors.FemAnimError`): Newmark with contact, the mixed formulation,
symplectic Euler, materials computing quadrature data outside UFL (corotated in 3D).
"""

from __future__ import annotations

import copy
import time

import numpy as np
from mpi4py import MPI

from fem_anim.adjoint.backward import BackwardSweep
from fem_anim.adjoint.parameters import ParameterSet
from fem_anim.adjoint.tape import Tape, choose_storage, record_forward
from fem_anim.errors import FemAnimError

__all__ = ["ADJOINT_OPTIONS", "AdjointModel", "gradient"]

#: The forward solver's tolerances while differentiating (below the command line's options):
#: each step converged far below the derivative's accuracy.
ADJOINT_OPTIONS = {"snes_rtol": "1e-14", "snes_atol": "5e-13"}


def check_differentiable(scene) -> None:
    """Refuse, with one line, what the adjoint does not cover.

    Raises:
        FemAnimError: naming the scene feature.
    """
    contact = bool(scene.get("obstacle")) or "contact" in scene.data
    if contact and scene["time"]["integrator"] == "newmark":
        raise FemAnimError("gradient: time.integrator = \"newmark\" with contact (obstacles "
                           "or [contact]) is not differentiable (implicit_euler or bdf2)")
    if scene["element"].get("formulation", "displacement") == "mixed":
        raise FemAnimError("gradient: element.formulation = \"mixed\" is not differentiable yet")
    if scene["time"]["integrator"] not in ("implicit_euler", "bdf2", "newmark"):
        raise FemAnimError(f"gradient: time.integrator = {scene['time']['integrator']!r} is "
                           "not differentiable (implicit_euler, bdf2 or newmark)")
    if scene["solver"]["mode"] != "exact":
        raise FemAnimError("gradient: solver.mode must be \"exact\" (a preview step is not "
                           "converged, so it has no derivative)")


def converged_scene(scene):
    """The scene with contact's default IPC step test replaced by the residual norm test.

    ``solver.stopping = "auto"`` stops a contact scene's Newton at IPC's step test, whose
    residual is only small against the step's forces (:mod:`fem_anim.solver.stopping`); a
    step's derivative holds at its stationary point, so the adjoint's forward steps are
    converged by ||r|| to :data:`ADJOINT_OPTIONS`' tolerances (or to the round-off floor).

    Returns:
        The scene itself, or a copy with ``solver.stopping = "norm"``.
    """
    contact = bool(scene.get("obstacle")) or "contact" in scene.data
    if not contact or scene["solver"]["stopping"] != "auto":
        return scene
    data = copy.deepcopy(scene.data)
    data["solver"]["stopping"] = "norm"
    return type(scene)._of(data, scene.source, scene.base_dir)


def exact_near_minimiser(minimiser, problem) -> None:
    """Let Newton switch IPC's Hessian from its per-pair projection to the exact one once
    its steps are small (as the ``"step"`` test does), under the norm test too: with the
    projection alone Newton converges only linearly near a resting contact and stalls at
    the round-off floor above the norm test's tolerance.

    Args:
        minimiser: The simulation's :class:`~fem_anim.solver.minimiser.Minimiser`.
        problem: Its :class:`~fem_anim.problem.objective.EnergyProblem` (with ``[contact]``).
    """
    from fem_anim.solver.stopping import scene_diagonal

    x = problem.domain.mesh.geometry.x[:, : problem.domain.mesh.geometry.dim]
    if not minimiser.step_tol:
        minimiser.step_tol = float(problem.scene["solver"]["step_tol"]) * \
            scene_diagonal(problem.comm, x)
    minimiser._exact_near = True
    # from the test's size itself, not EXACT_NEAR times it: under the adjoint's tight norm
    # test an exact direction taken that far out failed on the IPC cubes with BDF2, and the
    # projected Newton then stalled above the tolerance (tests/test_adjoint_contact.py)
    minimiser.exact_near_start = 1.0


class AdjointModel:
    """A scene ready to be run and differentiated many times (building it is collective).

    Args:
        scene: A validated :class:`~fem_anim.scene.schema.Scene`.
        params: Scene keys of the parameters (:func:`~fem_anim.adjoint.parameter_keys.expand_keys`).
        comm: MPI communicator.
        cli_options: PETSc options above :data:`ADJOINT_OPTIONS`.
        steps: Number of steps (default ``time.steps``); the step is ``time.dt``.
        storage: Where the forward states are kept (:mod:`fem_anim.adjoint.tape`):
            ``"memory"``, ``"revolve"`` (``checkpoints`` states in memory, the rest
            recomputed by the binomial schedule), ``"disk"``, or ``"auto"`` (memory while
            the states fit in :data:`~fem_anim.adjoint.tape.MEMORY_BUDGET`, else revolve).
        checkpoints: Revolve's most stored states (default: as many as fit the budget).

    Raises:
        FemAnimError: a scene feature or parameter the adjoint does not cover, or a bad
            storage or checkpoint count.
    """

    def __init__(self, scene, params: list[str], comm: MPI.Comm = MPI.COMM_WORLD,
                 cli_options: dict[str, str] | None = None, steps: int | None = None,
                 storage: str = "auto", checkpoints: int | None = None):
        from fem_anim.simulation.loop import Simulation

        check_differentiable(scene)
        scene = converged_scene(scene)
        self.scene = scene
        self.sim = Simulation(scene, comm, cli_options=ADJOINT_OPTIONS | (cli_options or {}))
        self.problem = p = self.sim.problem
        if p.ipc is not None:
            exact_near_minimiser(self.sim.minimiser, p)
        # the forward map as smooth as the solves allow: the landing's halving decides per
        # direction whether to halve or leave bt's cut, a decision that flips between nearby
        # parameters and moves the converged state within the solver's tolerance (J by up
        # to 2e-11 relative on tests/test_adjoint_initial.py's IPC cubes), which central
        # differences at 1e-7 m turn into 1e-5 relative errors; bt alone takes one path
        self.sim.minimiser.halving = False
        if p.quadrature_data:
            raise FemAnimError(f"gradient: material.model = {scene['material']['model']!r} "
                               "computes quadrature data outside UFL; not differentiable yet")
        self.parameters = ParameterSet(p, scene, params)
        self.sweep = BackwardSweep(p, self.parameters, self.sim.integrator.name == "newmark")
        self.steps = int(scene["time"]["steps"] if steps is None else steps)
        self.h = float(scene["time"]["dt"])
        ndofs = p.u.x.array.size
        #: the resolved storage and checkpoint count (:func:`~fem_anim.adjoint.tape.
        #: choose_storage`: decided from this rank's dofs, then the same on every rank)
        self.storage, self.checkpoints = comm.bcast(
            choose_storage(storage, checkpoints, self.steps, comm.allreduce(ndofs, op=MPI.MAX)),
            root=0)
        self.tape: Tape | None = None
        #: Wall time (s) of the last evaluation's forward run and backward sweep.
        self.timing = {"forward": 0.0, "backward": 0.0}
        self._bound: list = []  # kept alive: an id is unique only while its object lives

    @property
    def names(self) -> list[str]:
        """The scalar parameters, in the order of theta."""
        return self.parameters.names

    def forward(self, theta=None, objective=None) -> float | None:
        """Run forward at ``theta`` (default: the current values) and return J (or None)."""
        if theta is not None:
            self.parameters.assign(theta)
        self._record(objective)
        if objective is None:
            return None
        return objective.terms(self.tape)[0]

    def _record(self, objective) -> None:
        """The forward run, keeping the states the objective reads (collective)."""
        if self.tape is not None:
            self.tape.close()
        observed = None
        if objective is not None:
            self.bind(objective)
            try:
                observed = objective.steps(self.h, self.steps)
            except FemAnimError:  # a time off the steps: said by its terms, after the run
                observed = None
        self.tape = record_forward(self.sim, self.parameters, self.steps, self.h,
                                   self.storage, self.checkpoints, observed)
        self.timing["forward"] = self.tape.forward_s

    def evaluate(self, theta, objective) -> tuple[float, np.ndarray]:
        """J(theta) and dJ/dtheta (collective; the same on every rank).

        Raises:
            ConvergenceError: a forward step did not converge (the gradient is undefined).
        """
        self.parameters.assign(theta)
        self._record(objective)
        start = time.perf_counter()
        value, bars = objective.terms(self.tape)
        state_bars = [{} for _ in range(self.tape.steps + 1)]
        for n, fields in bars.items():
            state_bars[n] = {k: self.sweep.consistent(a) for k, a in fields.items()}
        grad = self.sweep.run(self.sim, self.tape, state_bars)
        self.timing["backward"] = time.perf_counter() - start
        return float(value), grad

    def set_initial_fields(self, u: np.ndarray | None = None,
                           v: np.ndarray | None = None) -> None:
        """Per-node initial displacement ``u`` and velocity ``v`` added to the scene's (and
        the parameters') u_0 and v_0 in the next runs (local dof arrays of V, ghosts
        included, e.g. ``model.problem.u.x.array``-shaped; pinned entries are ignored;
        None: none). Their gradient is :attr:`initial_gradient`."""
        pinned = self.sweep.pinned
        for key, field in (("u", u), ("v", v)):
            if field is None:
                self.parameters.nodal[key] = None
                continue
            field = np.array(field, dtype=float)
            if field.shape != self.problem.u.x.array.shape:
                raise FemAnimError(f"set_initial_fields: {key} has shape {field.shape}, the "
                                   f"displacement's local dofs {self.problem.u.x.array.shape}")
            field[pinned] = 0.0
            self.parameters.nodal[key] = field

    @property
    def initial_gradient(self) -> dict[str, np.ndarray]:
        """The last evaluation's dJ/du_0 and dJ/dv_0 per dof (``"u"``, ``"v"``: local dof
        arrays of V, ghosts equal to their owners, zero on pinned dofs): the gradient with
        respect to a per-node initial state (:meth:`set_initial_fields`). Sum products
        over the owned entries only (``model.sweep.dot``)."""
        return self.sweep.initial_bar

    def bind(self, objective) -> None:
        """Prepare an objective for this model, once (collective; raises its bad input,
        e.g. a target run on another mesh)."""
        if not any(o is objective for o in self._bound):
            objective.bind(self)
            self._bound.append(objective)


def gradient(scene, objective, params: list[str], comm: MPI.Comm = MPI.COMM_WORLD,
             cli_options: dict[str, str] | None = None, per_cell: bool = False,
             storage: str = "auto", checkpoints: int | None = None) -> tuple:
    """J and dJ/dtheta at the scene's own parameter values (collective).

    Args:
        scene: A validated :class:`~fem_anim.scene.schema.Scene` (``time.steps`` steps of
            ``time.dt`` are run).
        objective: An :class:`~fem_anim.adjoint.objectives.Objective`.
        params: Scene keys, e.g. ``["material.youngs_modulus", "initial.velocity"]``.
        comm: MPI communicator.
        cli_options: PETSc options for the forward solver.
        per_cell: Also return the gradient per cell (:mod:`fem_anim.adjoint.cell_gradient`).
        storage: ``"auto"``, ``"memory"``, ``"revolve"`` or ``"disk"`` (:class:`AdjointModel`).
        checkpoints: Revolve's most stored states.

    Returns:
        J, and {parameter name: dJ/dparameter}; with ``per_cell`` also {parameter name:
        DG0 Function of dJ/dtheta_c} for the parameters with one (materials, damping, an
        obstacle's friction).

    Raises:
        FemAnimError: a parameter the scene does not have or a feature not covered.
        ConvergenceError: a forward step did not converge.
    """
    model = AdjointModel(scene, params, comm, cli_options, storage=storage,
                         checkpoints=checkpoints)
    value, grad = model.evaluate(model.parameters.values(), objective)
    grads = dict(zip(model.names, map(float, grad)))
    cells = None
    if per_cell:
        from fem_anim.adjoint.cell_gradient import cell_functions

        cells = cell_functions(model)
    model.tape.close()
    return (value, grads) if cells is None else (value, grads, cells)
