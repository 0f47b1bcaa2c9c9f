"""Objectives J of a simulated motion, with their derivatives with respect to the states.

Each objective reads the forward run's states (:class:`~fem_anim.adjoint.tape.Tape`) and
returns J and dJ/du_n (and dJ/dv_n) for every state n it reads, as *additive* local dof
arrays: the entries of all ranks summed give the derivative (an entry is written on the
rank owning its dof). Times are given in seconds and must fall on a step (t = n h).

* :class:`PointTarget`: 1/2 |x_p(t) - target|^2 for the mesh vertex nearest a point;
* :class:`CentreOfMassTarget`: 1/2 |c(t) - target|^2, c = int rho x dV / int rho dV;
* :class:`TrajectoryMatch`: 1/2 sum over frames and vertices of |u - u_ref|^2, the
  reference a finished run (``fem_anim.open_run``) on the same mesh;
* :class:`StateFunctional`: a Python callable of the owned displacement entries, with its
  gradient;
* :class:`FormFunctional`: a UFL 0-form of the displacement, differentiated by
  ``ufl.derivative``.

Objectives add with ``+``. Binding one to a model (:meth:`Objective.bind`) is collective.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim.errors import FemAnimError
from fem_anim.output.files import VertexGather
from fem_anim.simulation.initial_state import center_of_mass

__all__ = ["CentreOfMassTarget", "FormFunctional", "Objective", "PointTarget",
           "StateFunctional", "TrajectoryMatch", "step_index"]


def step_index(t: float, h: float, steps: int) -> int:
    """The step n with n h = t (to 1e-9 h).

    Raises:
        FemAnimError: a time between steps or after the last one.
    """
    n = int(round(t / h))
    if abs(n * h - t) > 1e-9 * h or not 0 <= n <= steps:
        raise FemAnimError(f"objective time {t:g} s is not a step time of this run "
                           f"(h = {h:g} s, {steps} steps)")
    return n


class Objective:
    """An objective of the forward states; subclasses implement :meth:`terms`."""

    def bind(self, model) -> None:
        """Prepare for a model's problem (collective); called once per model."""
        self.model = model

    def terms(self, tape) -> tuple[float, dict[int, dict[str, np.ndarray]]]:
        """J (the same on every rank) and {n: {"u": dJ/du_n, "v": dJ/dv_n}} (additive)."""
        raise NotImplementedError

    def steps(self, h: float, steps: int) -> set[int] | None:
        """The state indices n whose u and v :meth:`terms` reads, for a run of ``steps``
        steps of ``h`` (None: possibly all; the revolve storage then keeps every u and v)."""
        return None

    def __add__(self, other: Objective) -> Objective:
        return Sum([self, other])


class Sum(Objective):
    """The sum of objectives."""

    def __init__(self, parts: list[Objective]):
        self.parts = []
        for part in parts:
            self.parts.extend(part.parts if isinstance(part, Sum) else [part])

    def bind(self, model) -> None:
        for part in self.parts:
            part.bind(model)

    def steps(self, h, steps):
        parts = [part.steps(h, steps) for part in self.parts]
        return None if any(s is None for s in parts) else set().union(*parts)

    def terms(self, tape):
        value, bars = 0.0, {}
        for part in self.parts:
            v, b = part.terms(tape)
            value += v
            for n, fields in b.items():
                into = bars.setdefault(n, {})
                for k, arr in fields.items():
                    into[k] = into[k] + arr if k in into else arr
        return value, bars


class PointTarget(Objective):
    """1/2 weight sum_t |X_p + u_p(t) - target_t|^2 (m^2) for the vertex p nearest ``point``.

    Args:
        point: A rest position (m); the nearest dof node is taken.
        targets: Target position(s) (m), one per time.
        times: The times (s).
        weight: A factor.
    """

    def __init__(self, point, targets, times, weight: float = 1.0):
        self.point = np.asarray(point, dtype=float)
        self.times = np.atleast_1d(np.asarray(times, dtype=float))
        self.targets = np.asarray(targets, dtype=float).reshape(len(self.times), -1)
        self.weight = float(weight)

    def bind(self, model) -> None:
        p = model.problem
        V = p.V
        owned = V.dofmap.index_map.size_local
        X = V.tabulate_dof_coordinates()[:owned, : p.d]
        dist = np.linalg.norm(X - self.point, axis=1)
        local = (float(dist.min()), p.comm.rank) if owned else (np.inf, p.comm.rank)
        best = min(p.comm.allgather(local))
        self.node = int(np.argmin(dist)) if p.comm.rank == best[1] else None
        self.X = X[self.node] if self.node is not None else None
        self.comm, self.d = p.comm, p.d

    def steps(self, h, steps):
        return {step_index(t, h, steps) for t in self.times}

    def terms(self, tape):
        value, bars = 0.0, {}
        for t, target in zip(self.times, self.targets):
            n = step_index(t, tape.h, tape.steps)
            du = np.zeros_like(tape.states[n].u)
            if self.node is not None:
                dofs = slice(self.node * self.d, (self.node + 1) * self.d)
                r = self.X + tape.states[n].u[dofs] - target
                value += 0.5 * self.weight * float(r @ r)
                du[dofs] = self.weight * r
            bars.setdefault(n, {})["u"] = bars.get(n, {}).get("u", 0.0) + du
        return self.comm.allreduce(value, op=MPI.SUM), bars


class CentreOfMassTarget(Objective):
    """1/2 weight sum_t |c(t) - target_t|^2 (m^2), c(t) = int rho (X + u) dV / int rho dV.

    With the mass-weighted dof sums m_i = int rho phi_i dV, c = c_0 + sum_i m_i u_i / m
    (exact for Lagrange elements; m = sum_i m_i).
    """

    def __init__(self, targets, times, weight: float = 1.0):
        self.times = np.atleast_1d(np.asarray(times, dtype=float))
        self.targets = np.asarray(targets, dtype=float).reshape(len(self.times), -1)
        self.weight = float(weight)

    def bind(self, model) -> None:
        p = model.problem
        self.comm, self.d = p.comm, p.d
        self.owned = p.V.dofmap.index_map.size_local * p.d
        dv = ufl.TestFunction(p.V)
        ones = ufl.as_vector([1.0] * p.d)
        b = fem_petsc.assemble_vector(fem.form(p.rho * ufl.inner(ones, dv) * ufl.dx))
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        m = np.zeros_like(p.u.x.array)
        m[: self.owned] = b.array
        b.destroy()
        self.m = m.reshape(-1, p.d)  # owned rows only nonzero
        self.total = self.comm.allreduce(self.m.sum(axis=0), op=MPI.SUM)
        self.c0 = center_of_mass(p)

    def steps(self, h, steps):
        return {step_index(t, h, steps) for t in self.times}

    def terms(self, tape):
        value, bars = 0.0, {}
        for t, target in zip(self.times, self.targets):
            n = step_index(t, tape.h, tape.steps)
            u = tape.states[n].u.reshape(-1, self.d)
            c = self.c0 + self.comm.allreduce((self.m * u).sum(axis=0), op=MPI.SUM) / self.total
            r = c - target
            value += 0.5 * self.weight * float(r @ r)
            du = (self.weight * r / self.total * self.m).reshape(-1)
            bars.setdefault(n, {})["u"] = bars.get(n, {}).get("u", 0.0) + du
        return value, bars


class TrajectoryMatch(Objective):
    """1/2 weight sum_frames sum_vertices |u(t_f) - u_ref(t_f)|^2 (m^2).

    Args:
        reference: A finished run's directory (or a :class:`fem_anim.Run`) on the same mesh;
            every frame after the first whose time is a step of the forward run is matched.
        weight: A factor.

    Raises:
        FemAnimError: (at :meth:`bind`) a reference on another mesh, or with no frame at a
            step time.
    """

    def __init__(self, reference, weight: float = 1.0):
        self.reference = reference
        self.weight = float(weight)

    def bind(self, model) -> None:
        from fem_anim.runs import open_run

        p = model.problem
        run = self.reference if not isinstance(self.reference, (str, Path)) else \
            open_run(self.reference)
        gather = VertexGather(p.domain, p.V)
        points = p.domain.mesh.geometry.x[:, : p.d]
        ref_points = run.points
        index = np.asarray(gather.input_index, dtype=np.int64)
        n_points = gather.num_points
        same = ref_points.shape == (n_points, p.d) and np.allclose(
            ref_points[index], points, rtol=0.0, atol=1e-9 * max(1.0, np.abs(points).max(
                initial=0.0)))
        if not p.comm.allreduce(bool(same), op=MPI.LAND):
            raise FemAnimError(f"target run {run.outdir} was made on another mesh "
                               f"({ref_points.shape[0]} vertices, this scene {n_points})")
        owned = p.V.dofmap.index_map.size_local
        keep = gather.node_to_dof < owned  # each owned vertex once
        self.dofs = gather.node_to_dof[keep]
        self.index = index[keep]
        self.comm, self.d = p.comm, p.d
        self.frames = [(float(t), run.displacement(f)) for f, t in enumerate(run.times) if f > 0]

    def steps(self, h, steps):
        return {step_index(t, h, steps) for t, _ in self.frames
                if t <= steps * h * (1.0 + 1e-12)}

    def terms(self, tape):
        value, bars = 0.0, {}
        matched = 0
        for t, ref in self.frames:
            if t > tape.steps * tape.h * (1.0 + 1e-12):
                continue
            n = step_index(t, tape.h, tape.steps)
            matched += 1
            u = tape.states[n].u.reshape(-1, self.d)
            r = u[self.dofs] - ref[self.index]
            value += 0.5 * self.weight * float((r * r).sum())
            du = np.zeros_like(u)
            du[self.dofs] = self.weight * r
            bars.setdefault(n, {})["u"] = bars.get(n, {}).get("u", 0.0) + du.reshape(-1)
        if not matched:
            raise FemAnimError("target run has no frame within the simulated time")
        return self.comm.allreduce(value, op=MPI.SUM), bars


class StateFunctional(Objective):
    """J = sum over ranks of fn(u_owned) at one time (default: the last state).

    Args:
        fn: Takes the owned displacement entries (a flat array, node-major, m) and returns
            (its part of J, its gradient: an array like its argument). The parts of all
            ranks are summed, so fn must be a sum over dofs (a separable functional).
        time: The time (s), or None for the final state.
    """

    def __init__(self, fn, time: float | None = None):
        self.fn, self.time = fn, time

    def bind(self, model) -> None:
        p = model.problem
        self.comm = p.comm
        self.owned = p.V.dofmap.index_map.size_local * p.d

    def steps(self, h, steps):
        return {steps if self.time is None else step_index(self.time, h, steps)}

    def terms(self, tape):
        n = tape.steps if self.time is None else step_index(self.time, tape.h, tape.steps)
        u = tape.states[n].u
        value, grad = self.fn(u[: self.owned].copy())
        du = np.zeros_like(u)
        du[: self.owned] = grad
        return self.comm.allreduce(float(value), op=MPI.SUM), {n: {"u": du}}


class FormFunctional(Objective):
    """J = the UFL 0-form ``build(u)`` of the displacement Function u at one time.

    Args:
        build: u -> a UFL 0-form (e.g. ``lambda u: u[2] * ufl.dx``); it must not involve
            the parameters (its derivative with respect to them is not taken).
        time: The time (s), or None for the final state.
    """

    def __init__(self, build, time: float | None = None):
        self.build, self.time = build, time

    def bind(self, model) -> None:
        p = self.problem = model.problem
        self.u = fem.Function(p.V, name="objective_state")
        form = self.build(self.u)
        self.value_form = fem.form(form)
        self.gradient_form = fem.form(ufl.derivative(form, self.u, ufl.TestFunction(p.V)))
        self.owned = p.V.dofmap.index_map.size_local * p.d

    def steps(self, h, steps):
        return {steps if self.time is None else step_index(self.time, h, steps)}

    def terms(self, tape):
        n = tape.steps if self.time is None else step_index(self.time, tape.h, tape.steps)
        self.u.x.array[:] = tape.states[n].u
        value = self.problem.comm.allreduce(fem.assemble_scalar(self.value_form), op=MPI.SUM)
        b = fem_petsc.assemble_vector(self.gradient_form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        du = np.zeros_like(self.u.x.array)
        du[: self.owned] = b.array
        b.destroy()
        return float(value), {n: {"u": du}}
