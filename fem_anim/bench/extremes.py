"""Stability at the extremes: what each hard scene is expected to do, and what it does.

    fem-anim bench --extremes [--full] [--set KEY=VALUE ...] [--no-locking] [-o TABLE.md]

Each :class:`Case` is a scene pushed to an extreme (Young's modulus 1e2 to 1e9 Pa,
Poisson ratio up to 0.4999, dt from 1e-5 to 1 s, a spinning body, a stretched and a
fully compressed bar, elements of aspect ratio 50 and more, a press that inverts
elements in one step). Its expected outcome is derived from the scene by
:func:`expected_outcome` (the maths is there), not copied from a run:

- :data:`FINISHES`: the continuous problem is well posed, the run must complete, either
  ``converges-bounded`` (every step converges at once) or ``recovers-by-substepping``
  (some steps fail, the adaptive stepper halves dt and the run completes,
  :class:`fem_anim.simulation.loop.AdaptiveStepper`); which of the two is solver behaviour,
  reported in the table but not expected;
- ``recovers-by-substepping``: the first step's pin motion alone inverts a layer of
  elements, the full step cannot start, a smaller one can;
- ``stops-with-message``: the pins close the body's thickness to zero: no admissible
  state, the run stops with a :class:`~fem_anim.errors.ConvergenceError`;
- ``fails the physical check``: the linear material on a spinning body (seed eq. 36).

A completed run is also *bounded*: in a conservative scene (no damping, no moving pins)
the total energy never exceeds its initial value E_0 by more than
:data:`ENERGY_GROWTH_BOUND` times the exchanged energy (:mod:`fem_anim.simulation.energy_report`); with
moving pins (which do work on the body) it stays finite. A case may add its own check:
the spinning body keeps its volume after half a turn; the stiffest beam (E = 1e9 Pa,
small strains: nearly linear), released from rest under its weight, never deflects
beyond twice the static deflection of beam theory (:func:`sag_bound`).

:func:`run_case` measures the outcome; :func:`locking_rows` measures what volumetric
locking does to P1 against P2 at nu = 0.4999 (quasi-static tip deflection under gravity).
The fast variants (2D, coarse, few steps) run in CI; ``--full`` runs the 3D grid.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fem_anim.errors import ConvergenceError, FemAnimError, SceneError
from fem_anim.mesh.build import cell_volumes
from fem_anim.scene.loading import load_scene

__all__ = ["Case", "Outcome", "cases", "run_case", "locking_rows", "mixed_locking_rows",
           "format_table", "main", "scene_text", "OUTCOMES", "COMPLETED", "ENERGY_GROWTH_BOUND",
           "FINISHES", "sag_bound", "expected_outcome", "matches", "pin_displacement",
           "pinned_gaps"]

OUTCOMES = ("converges-bounded", "recovers-by-substepping", "stops-with-message")

#: Measured outcomes of a run that reached its last step (the linear spinning body does, and
#: then fails the check its physics predicts).
COMPLETED = ("converges-bounded", "recovers-by-substepping", "fails the physical check")

#: Largest rise of the total energy above E_0 in a conservative scene, as a fraction of the
#: exchanged energy (:func:`fem_anim.simulation.energy_report.energy_report`: the largest of |E_0|, the
#: kinetic energy and the drop of the potential energy over the run). The continuous
#: system conserves E (kinetic K plus potential P); implicit Euler's step satisfies
#: M (v_{n+1} - v_n) = -h grad P(x_{n+1}), and for a P convex along the step this gives
#: K_{n+1} + P_{n+1} + 1/2 ||v_{n+1} - v_n||_M^2 <= K_n + P_n (it only loses energy);
#: Newmark (the trapezoidal rule) conserves E exactly for a quadratic energy, and a
#: nonlinear one changes it by O(dt^2) relative to the strain energy's nonlinear part,
#: small at the strains of these cases; the Newton tolerance adds |r| |dx| per step
#: (round-off level at rtol 1e-8). A rise of 1 % is none of these: it is a scheme or a
#: term that creates energy. (Measured at most 1.2e-4 in the 2D variants, 3.4e-5 in 3D.)
ENERGY_GROWTH_BOUND = 1e-2


@dataclass
class Case:
    """One extreme scene: name, the scene's keys, expected outcome, optional check."""

    name: str
    keys: dict
    expected: str
    steps: int
    check: str = ""  # "rigid": a rotation keeps the volume (a spinning body); "sag": the
    # tip of a stiff cantilever released under gravity never deflects beyond the bound of
    # :func:`sag_bound`


@dataclass
class Outcome:
    """What a case did."""

    measured: str
    detail: str
    seconds: float
    info: dict = field(default_factory=dict)


def scene_text(data: dict) -> str:
    """A scene dictionary as TOML (numbers, strings, booleans, lists of numbers)."""
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        return json.dumps(v) if isinstance(v, (str, list)) else repr(float(v)) \
            if isinstance(v, float) else str(v)

    lines = [f"name = {json.dumps(data.get('name', 'extreme'))}"]
    for section, table in data.items():
        if section == "name":
            continue
        for entry in (table if isinstance(table, list) else [table]):
            lines.append(f"[[{section}]]" if isinstance(table, list) else f"[{section}]")
            lines += [f"{k} = {value(v)}" for k, v in entry.items()]
    return "\n".join(lines) + "\n"


def _beam(dim: int, full: bool, size=None, es=None, gravity=True, **sections) -> dict:
    """A cantilever (pinned at x = 0) of 1 x 0.2 (x 0.2) m, neo-Hookean, E = 1e5 Pa."""
    size = size or ([1.0, 0.2, 0.2][:dim])
    data = {"name": "extreme",
            "mesh": {"dim": dim, "size": size, "element_size": es or (0.05 if full else 0.1)},
            "material": {"youngs_modulus": 1.0e5, "poisson_ratio": 0.3},
            "time": {"dt": 1.0 / 30.0},
            "pin": [{"name": "wall", "min": [-1e-6] + [-10.0] * (dim - 1),
                     "max": [1e-6] + [10.0] * (dim - 1)}],
            "output": {"render": False}}
    if gravity:
        data["gravity"] = {"acceleration": [0.0] * (dim - 1) + [-9.81]}
    for section, table in sections.items():
        data[section] = data.get(section, {}) | table if isinstance(table, dict) else table
    return data


def cases(full: bool = False) -> list[Case]:
    """The extreme cases: 2D and coarse (CI), or 3D and finer with more values (``--full``).

    Each case's expected outcome is :func:`expected_outcome` of its scene."""
    out = _cases(full)
    for case in out:
        case.expected = expected_outcome(case)
    return out


def _cases(full: bool) -> list[Case]:
    d = 3 if full else 2
    n = 2 if full else 1  # more steps in the full grid
    out = []
    for E in ([1e2, 1e4, 1e6, 1e9] if full else [1e2, 1e9]):
        out.append(Case(f"E = {E:.0e} Pa", _beam(d, full, material={"youngs_modulus": E}),
                        "", (15 if E <= 1e2 else 6) * n,
                        check="sag" if E >= 1e9 else ""))
    for nu in ([0.45, 0.49, 0.4999] if full else [0.4999]):
        if nu == 0.4999:  # the Taylor-Hood (u, p) formulation where P1 and P2 struggle
            out.append(Case(f"nu = {nu}, P2/P1 mixed", _beam(
                d, full, material={"poisson_ratio": nu}, solver={"preset": "ldlt"},
                element={"degree": 2, "formulation": "mixed"},
                time={"dt": 1.0 / 30.0, "min_dt": 1.0 / 480.0}), "", 4 * n))
        for p in (1, 2):
            # the floor of adaptive halving at dt/16: a stalled 3D P2 run stops in a minute
            out.append(Case(f"nu = {nu}, P{p}", _beam(
                d, full, material={"poisson_ratio": nu}, element={"degree": p},
                time={"dt": 1.0 / 30.0, "min_dt": 1.0 / 480.0}),
                "", 4 * n))
    for dt in ([1e-5, 1e-3, 1e-1, 1.0] if full else [1e-5, 1.0]):
        out.append(Case(f"dt = {dt:g} s", _beam(d, full, time={"dt": dt}),
                        "", 3 * n))
    axis = {"axis": [0.0, 0.0, 1.0]} if d == 3 else {}
    centre = [0.5, 0.1, 0.1][:d]
    hub = {"name": "hub", "min": [0.4] + [0.0] * (d - 1), "max": [0.6] + [0.2] * (d - 1),
           "angular_velocity": math.pi, "center": centre, **axis}
    for model in ("neohookean", "linear"):
        out.append(Case(f"spinning body (half a turn in 1 s), {model}", _beam(
            d, full, gravity=False, pin=[hub], material={"youngs_modulus": 1e7, "model": model},
            time={"dt": 1.0 / 30.0}), "", 30, check="rigid"))
    right = {"name": "end", "min": [1.0 - 1e-6] + [-10.0] * (d - 1),
             "max": [1.0 + 1e-6] + [10.0] * (d - 1)}
    wall = _beam(d, full)["pin"][0]
    out.append(Case("stretched to 3x length", _beam(
        d, full, gravity=False, time={"dt": 0.1},
        pin=[wall, right | {"velocity": [2.0] + [0.0] * (d - 1), "until": 1.0}]),
        "", 10))
    floor = {"name": "floor", "min": [-10.0] * (d - 1) + [-1e-6],
             "max": [10.0] * (d - 1) + [1e-6]}
    press = {"name": "press", "min": [-10.0] * (d - 1) + [0.2 - 1e-6],
             "max": [10.0] * (d - 1) + [0.2 + 1e-6]}
    out.append(Case("crushed to zero thickness", _beam(
        d, full, gravity=False, time={"dt": 0.1},
        pin=[floor, press | {"velocity": [0.0] * (d - 1) + [-0.2], "until": 1.0}]),
        "", 10))
    out.append(Case("press inverts elements in one step", _beam(
        d, full, gravity=False, time={"dt": 0.1},
        pin=[wall, right | {"velocity": [-4.0] + [0.0] * (d - 1), "until": 0.1}]),
        "", 3))
    thin = [2.0, 0.02, 0.02][:d]
    out.append(Case("thin elements (aspect >= 50)", _beam(
        d, full, size=thin, es=1.0, material={"youngs_modulus": 1e8}, time={"dt": 0.01}),
        "", 5 * n))
    return out


#: The expected outcome of a case whose continuous problem is well posed: the run completes,
#: converging at once or recovering by substepping. Which of the two is the solver's
#: behaviour, not the scene's: the table reports it, the expectation does not fix it.
FINISHES = "finishes"


def matches(expected: str, measured: str) -> bool:
    """Whether a measured outcome is the expected one (:data:`FINISHES` takes either of
    ``converges-bounded`` and ``recovers-by-substepping``)."""
    return measured == expected or (expected == FINISHES and measured in OUTCOMES[:2])


def pin_displacement(pin: dict, t: float) -> np.ndarray:
    """The translation a pin prescribes at time t: v min(t, until) (v = 0 without a velocity;
    a hub's rotation is rigid and changes no thickness)."""
    v = np.asarray(pin.get("velocity", [0.0] * len(pin["min"])), dtype=float)
    until = pin.get("until")
    return v * (t if until is None else min(t, until))


def pinned_gaps(keys: dict, steps: int) -> list[dict]:
    """The body's thickness between each pair of pins that hold two opposite faces.

    A pin that is a plane x_a = c (its box thinner than 1e-3 m along a) spanning the whole
    face of the box-shaped body [0, size] holds that face. Two such planes on the same axis
    at c_1 < c_2 hold the body's thickness there: at time t it is
    g(t) = c_2 - c_1 + (d_2(t) - d_1(t))_a with d_i = :func:`pin_displacement`. Returns, per
    pair, the axis, g(0), the smallest g(t_n) over the run's step times t_n = n dt, and the
    first step's closing g(0) - g(dt).
    """
    dim, size = keys["mesh"]["dim"], np.asarray(keys["mesh"]["size"], dtype=float)
    dt = keys["time"]["dt"]
    planes = []
    for pin in keys.get("pin", []):
        lo, hi = np.asarray(pin["min"], dtype=float), np.asarray(pin["max"], dtype=float)
        thin = np.flatnonzero(hi - lo < 1e-3)
        if thin.size != 1:
            continue
        a, c = int(thin[0]), 0.5 * (lo[thin[0]] + hi[thin[0]])
        others = np.arange(dim) != a
        if (abs(c) < 1e-3 or abs(c - size[a]) < 1e-3) and \
                np.all(lo[others] <= 0.0) and np.all(hi[others] >= size[others]):
            planes.append((a, c, pin))
    times = dt * np.arange(steps + 1)
    rows = []
    for i, (a, c1, p1) in enumerate(planes):
        for b, c2, p2 in planes[i + 1:]:
            if b != a or abs(c2 - c1) < 1e-3:
                continue
            (c1, p1), (c2, p2) = sorted([(c1, p1), (c2, p2)], key=lambda e: e[0])
            gap = np.array([c2 - c1 + pin_displacement(p2, t)[a] - pin_displacement(p1, t)[a]
                            for t in times])
            rows.append({"axis": a, "initial": float(gap[0]), "smallest": float(gap.min()),
                         "first_closing": float(gap[0] - gap[min(1, steps)])})
    return rows


def expected_outcome(case: Case) -> str:
    """What the physics of a case's scene says it must do (not a run's result).

    In order:

    - The linear material on a spinning body: psi = mu |eps|^2 + lambda/2 tr(eps)^2 with
      eps = sym(F) - I is not rotation invariant (seed eq. 36): a rotation R by theta has
      eps = (cos theta - 1) I in the plane of the turn, energy where there is no strain; the
      energy's minimiser under a rotation is not the rotated body, so it
      ``fails the physical check`` (volume kept after half a turn).
    - Pins that hold two opposite faces and close the gap between them to
      g <= 0 (:func:`pinned_gaps`): the body must fit in zero thickness. A body that stays
      between its pinned faces then has zero volume there, so det F > 0 is impossible and
      the energy (neo-Hookean: -mu ln J -> infinity as J -> 0) has no finite value: the step
      has no admissible solution. The only states with det F > 0 fold the whole body out
      of the gap through one side (every fibre across the gap stretched by a factor >= 2 x/h
      for its distance x from that side), which an implicit step from the squeezed body does
      not reach: the run ``stops-with-message``, and the message must name the inversion.
    - A first step whose pin motion alone closes a gap by at least one element size h
      (``mesh.element_size``; the body at rest): the start Newton is given (the pins moved,
      every other node where inertia puts it, i.e. at rest) moves the pinned face onto or
      past its neighbouring layer of nodes, so every element of that layer has det F <= 0 at
      the start and the full step cannot begin; while the final gap is positive the
      problem is well posed at a smaller dt, so the run ``recovers-by-substepping``.
    - Otherwise the continuous problem is well posed (positive thickness, a hyperelastic
      energy that is rotation invariant, finite loads) and the run must complete:
      :data:`FINISHES`. Whether a step needs substeps is the solver's business: reported,
      not expected.
    """
    if case.check == "rigid" and case.keys["material"].get("model") == "linear":
        return "fails the physical check"
    gaps = pinned_gaps(case.keys, case.steps)
    if any(g["smallest"] <= 1e-12 * g["initial"] for g in gaps):
        return "stops-with-message"
    if any(g["first_closing"] >= case.keys["mesh"]["element_size"] for g in gaps):
        return "recovers-by-substepping"
    return FINISHES


def sag_bound(youngs_modulus: float, poisson_ratio: float, dim: int, length: float = 1.0,
              height: float = 0.2, density: float = 1000.0, g: float = 9.81) -> float:
    """Largest tip deflection of a cantilever released from rest under its own weight.

    A load applied suddenly to a linear system at rest gives at most twice the static
    displacement (energy: 1/2 k w^2 - q w <= 0, so w <= 2 q / k), and Newmark, the
    trapezoidal rule, conserves that energy exactly for a linear system. The static tip
    deflection of a cantilever under its own weight is Euler-Bernoulli's
    w = q L^4 / (8 E' I) = 3 rho g L^4 / (2 E' h^2) (E' = E / (1 - nu^2) in plane strain),
    plus Timoshenko's shear term q L^2 / (2 kappa G A): a ratio 4 E' I / (kappa G A L^2)
    (kappa = 5/6) to the bending part. A coarse P1 mesh is stiffer than both, so the bound
    holds with room; a doubled load or a halved stiffness breaks it.
    """
    e_eff = youngs_modulus / (1 - poisson_ratio ** 2) if dim == 2 else youngs_modulus
    bending = 3 * density * g * length ** 4 / (2 * e_eff * height ** 2)
    shear_modulus = youngs_modulus / (2 * (1 + poisson_ratio))
    shear = 4 * e_eff * height ** 2 / 12 / (5 / 6 * shear_modulus * length ** 2)
    return 2.0 * bending * (1.0 + shear)


def _aspect_ratio(points: np.ndarray, cells: np.ndarray) -> float:
    """Largest (longest edge / smallest height) over the cells (vectorised)."""
    x = points[cells]
    d = cells.shape[1] - 1
    edges = [x[:, j] - x[:, i] for i in range(d + 1) for j in range(i + 1, d + 1)]
    longest = np.max([np.linalg.norm(e, axis=1) for e in edges], axis=0)
    measure = np.abs(cell_volumes(points, cells))
    faces = [np.delete(x, i, axis=1) for i in range(d + 1)]
    if d == 2:
        face_size = [np.linalg.norm(f[:, 1] - f[:, 0], axis=1) for f in faces]
    else:
        face_size = [0.5 * np.linalg.norm(np.cross(f[:, 1] - f[:, 0], f[:, 2] - f[:, 0]),
                                           axis=1) for f in faces]
    height = d * measure / np.max(face_size, axis=0)
    return float(np.max(longest / height))


def _load(data: dict, overrides: list[str] = ()):
    """Validate a scene dictionary exactly as a file, with ``--set KEY=VALUE`` overrides
    (each rank reads its own copy)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "case.toml"
        path.write_text(scene_text(data))
        return load_scene(path, list(overrides))


def _volume_change(sim, state) -> float | None:
    """Relative volume change of the deformed mesh (collective gather; rank 0 computes)."""
    u = sim.gather.gather(state.u)
    if sim.comm.rank != 0:
        return None
    x, cells = sim.domain.points, sim.domain.cells
    return float(cell_volumes(x + u, cells).sum() / cell_volumes(x, cells).sum() - 1.0)


def run_case(case: Case, comm=None, overrides: list[str] = ()) -> Outcome:
    """Run a case to its end or its error and classify what happened.

    ``overrides`` are ``KEY=VALUE`` strings applied to the case's scene as ``fem-anim run
    --set`` does (e.g. ``solver.hessian=auto``)."""
    from mpi4py import MPI

    from fem_anim.simulation.energy_report import energy_report, initial_energies
    from fem_anim.simulation.loop import AdaptiveStepper, Simulation

    comm = comm or MPI.COMM_WORLD
    data = case.keys | {"time": case.keys["time"] | {"steps": case.steps}}
    scene = _load(data, overrides)
    start = time.perf_counter()
    sim = Simulation(scene, comm, {})
    info = {"dofs": sim.problem.V.dofmap.index_map.size_global * sim.problem.d}
    info["aspect"] = comm.bcast(_aspect_ratio(sim.domain.points, sim.domain.cells)
                                if comm.rank == 0 else None, root=0)
    initial = initial_energies(sim)
    dt = scene["time"]["dt"]
    stepper = AdaptiveStepper(sim, dt, scene["time"])
    state, rows = sim.initial_state(), []
    tip = None
    if case.check == "sag":
        from fem_anim.bench.measure import PointSampler

        tip = PointSampler(sim.domain.mesh, np.array([[1.0, 0.1, 0.1][:sim.problem.d]]))
        deflections = []
    try:
        for frame in range(1, case.steps + 1):
            for state, row in stepper.advance(state, frame * dt):
                rows.append(row)
                if tip is not None:
                    sim.problem.u.x.array[:] = state.u
                    deflections.append(-tip.sample(sim.problem.u)[0, -1])
    except ConvergenceError as err:
        message = str(err)  # its start (where) and its end (what to do) fit in a table cell
        if len(message) > 200:
            message = f"{message[:110]} ... {message[-85:]}"
        return Outcome("stops-with-message", message, time.perf_counter() - start, info)
    seconds = time.perf_counter() - start
    report = energy_report(rows, initial, scene)
    retries = sum(r["retries"] for r in rows)
    info |= {"retries": retries, "newton_its": sum(r["newton_its"] for r in rows),
             "drift": report["drift"], "excursion": report["max_excursion"]}
    detail = f"{len(rows)} steps, {retries} retries, {info['newton_its']} Newton its"
    bounded = checked = all(math.isfinite(r["total_energy"]) for r in rows)
    if report["conservative"]:  # no growth beyond ENERGY_GROWTH_BOUND (a loss is damping)
        e0, scale = report["initial_energy"], report["exchanged_energy"]
        growth = (max(r["total_energy"] for r in rows) - e0) / scale if scale > 0 else 0.0
        info["growth"] = growth
        bounded &= growth <= ENERGY_GROWTH_BOUND
        if report["drift"] is not None:  # None: nothing moved above round-off
            detail += f", energy drift {100 * report['drift']:+.2g} %"
        detail += f", largest rise {100 * growth:.2g} %"
    if case.check == "rigid":  # rotation invariance: a turn does not inflate the body
        change = comm.bcast(_volume_change(sim, state), root=0)
        checked = abs(change) < 0.05
        info["volume_change"] = change
        detail += f", volume change {100 * change:+.2g} % after the half turn"
    if case.check == "sag":
        material = scene["material"]
        bound = sag_bound(material["youngs_modulus"], material["poisson_ratio"], sim.problem.d)
        info["sag_ratio"] = max(deflections) / bound
        checked = 0.0 < max(deflections) <= bound
        detail += f", tip sag {max(deflections):.3g} m <= bound {bound:.3g} m"
    if info["aspect"] >= 10:
        detail += f", aspect ratio {info['aspect']:.0f}"
    if not bounded or not checked:
        return Outcome("unbounded energy" if not bounded else "fails the physical check",
                       detail, seconds, info)
    return Outcome("recovers-by-substepping" if retries else "converges-bounded", detail,
                   seconds, info)


def locking_rows(full: bool = False, comm=None) -> list[dict]:
    """Volumetric locking: quasi-static tip deflection of P1 and P2 against a fine P2 run.

    A cantilever (E = 1e7 Pa, so the deflection is small) under gravity, brought to rest
    by implicit Euler with dt = 1 s (each step damps the first mode by 1 / (1 + (w h)^2),
    w ~ 20 rad/s). Near incompressibility P1 simplices lock: the discrete displacements
    must be nearly divergence-free on every element, which P1 tetrahedra/triangles can
    hardly satisfy, so the beam comes out far too stiff; P2 does not lock this way. The
    reference is P2 on a mesh twice as fine; Euler-Bernoulli gives
    w = 3 rho g L^4 / (2 E' h^2) (E' = E / (1 - nu^2) in plane strain) for scale.
    """
    from mpi4py import MPI

    comm = comm or MPI.COMM_WORLD
    d = 3 if full else 2
    es = 0.1  # the fine P2 reference at 0.05: 3D P2 at 0.025 would be 8e4 dofs
    rows = []
    for nu in (0.3, 0.4999):
        deflection = {}
        for label, degree, size in (("P1", 1, es), ("P2", 2, es), ("fine P2", 2, es / 2)):
            data = _beam(d, full, es=size, material={"youngs_modulus": 1e7, "poisson_ratio": nu},
                         element={"degree": degree},
                         time={"dt": 1.0, "steps": 3, "integrator": "implicit_euler"})
            deflection[label] = _settled_tip(data, comm)
        e_eff = 1e7 / (1 - nu ** 2) if d == 2 else 1e7
        beam_theory = 3 * 1000.0 * 9.81 / (2 * e_eff * 0.2 ** 2)
        for label in ("P1", "P2"):
            rows.append({"nu": nu, "element": label, "deflection": deflection[label],
                         "reference": deflection["fine P2"], "beam_theory": beam_theory,
                         "ratio": deflection[label] / deflection["fine P2"]})
    return rows


def _settled_tip(data: dict, comm) -> float:
    """Downward tip deflection after 3 implicit Euler steps of 1 s (the beam at rest)."""
    from fem_anim.simulation.loop import AdaptiveStepper, Simulation
    from fem_anim.bench.measure import PointSampler

    scene = _load(data)
    sim = Simulation(scene, comm, {})
    stepper = AdaptiveStepper(sim, 1.0, scene["time"])
    state = sim.initial_state()
    for frame in (1, 2, 3):
        for state, _ in stepper.advance(state, float(frame)):
            pass
    sim.problem.u.x.array[:] = state.u
    d = sim.problem.d
    tip = np.array([[1.0, 0.1, 0.1][:d]])
    return -PointSampler(sim.domain.mesh, tip).sample(sim.problem.u)[0, -1]


def mixed_locking_rows(full: bool = False, comm=None) -> list[dict]:
    """The locking study's rows of the mixed formulation (Taylor-Hood P2/P1, ``ldlt``).

    The cantilever of :func:`locking_rows` at nu = 0.49, 0.499, 0.4999 and 0.5 (exactly
    incompressible, which no displacement element can express), against the mixed
    formulation on a mesh twice as fine.
    """
    from mpi4py import MPI

    comm = comm or MPI.COMM_WORLD
    d = 3 if full else 2
    es = 0.1
    rows = []
    for nu in (0.49, 0.499, 0.4999, 0.5):
        deflection = {}
        for label, size in (("P2/P1 mixed", es), ("fine", es / 2)):
            data = _beam(d, full, es=size, material={"youngs_modulus": 1e7, "poisson_ratio": nu},
                         element={"degree": 2, "formulation": "mixed"}, solver={"preset": "ldlt"},
                         time={"dt": 1.0, "steps": 3, "integrator": "implicit_euler"})
            deflection[label] = _settled_tip(data, comm)
        e_eff = 1e7 / (1 - nu ** 2) if d == 2 else 1e7
        rows.append({"nu": nu, "element": "P2/P1 mixed", "deflection": deflection["P2/P1 mixed"],
                     "reference": deflection["fine"],
                     "beam_theory": 3 * 1000.0 * 9.81 / (2 * e_eff * 0.2 ** 2),
                     "ratio": deflection["P2/P1 mixed"] / deflection["fine"]})
    return rows


def format_table(results: list[tuple[Case, Outcome]], locking: list[dict], full: bool) -> str:
    """The markdown tables: expected against measured outcome, and the locking study."""
    lines = [f"Stability at the extremes ({'full 3D grid' if full else 'fast 2D variants'})",
             "", "| case | expected | measured | | details | s |", "|---|---|---|---|---|---|"]
    for case, out in results:
        mark = "ok" if matches(case.expected, out.measured) else \
            "not run" if out.measured == "not run" else "**differs**"
        lines.append(f"| {case.name} | {case.expected} | {out.measured} | {mark} | "
                     f"{out.detail.replace('|', '/')} | {out.seconds:.1f} |")
    ran = [(case, out) for case, out in results
           if out.measured != "not run" and case.expected != "stops-with-message"]
    done = sum(out.measured in COMPLETED for _, out in ran)
    lines += ["", f"{done} of the {len(ran)} cases run whose physics says they finish "
              f"converge or recover ({100 * done / max(len(ran), 1):.0f} %)"]
    if not locking:
        return "\n".join(lines) + "\n"
    lines += ["", "Locking: quasi-static tip deflection under gravity (E = 1e7 Pa), "
              "against P2 on a mesh twice as fine (the mixed rows: against the mixed "
              "formulation on it)", "",
              "| nu | element | deflection (m) | fine P2 (m) | beam theory (m) | ratio |",
              "|---|---|---|---|---|---|"]
    for r in locking:
        lines.append(f"| {r['nu']} | {r['element']} | {r['deflection']:.4g} | "
                     f"{r['reference']:.4g} | {r['beam_theory']:.4g} | {r['ratio']:.3f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    """``fem-anim bench --extremes [--full] [-o FILE.md]``: run, print (and write) the table.

    Returns 0 when every case did what it is expected to do, 1 otherwise, 2 on bad input.
    """
    from mpi4py import MPI

    from fem_anim.console import print_error, quiet_jit_logging

    parser = argparse.ArgumentParser(prog="fem-anim bench --extremes")
    parser.add_argument("--full", action="store_true", help="the 3D grid (minutes)")
    parser.add_argument("-o", "--output", help="also write the table to this markdown file")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="override a scene key in every case")
    parser.add_argument("--no-locking", action="store_true", help="the grid only, no locking study")
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        print_error(f"bench --extremes: unrecognized arguments: {' '.join(unknown)}")
        return 2
    quiet_jit_logging()
    try:
        results = []
        for case in cases(args.full):
            try:
                results.append((case, run_case(case, overrides=args.overrides)))
            except SceneError as err:  # an override this case's scene refuses
                if not args.overrides:
                    raise
                results.append((case, Outcome("not run", str(err).replace("\n", " "), 0.0)))
            if MPI.COMM_WORLD.rank == 0 and not args.quiet:
                print(f"extremes: {case.name}: {results[-1][1].measured} "
                      f"({results[-1][1].seconds:.1f} s)", file=sys.stderr, flush=True)
        locking = [] if args.no_locking else \
            locking_rows(args.full) + mixed_locking_rows(args.full)
    except FemAnimError as err:
        print_error(str(err))
        return 2
    if results and all(out.measured == "not run" for _, out in results):
        print_error(results[0][1].detail)  # refused everywhere: bad input, not a case's limit
        return 2
    table = format_table(results, locking, args.full)
    if MPI.COMM_WORLD.rank == 0:
        print(table)
        if args.output:
            from fem_anim.bench.trade import machine_description

            stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
            command = " ".join(["fem-anim bench --extremes", *argv])
            Path(args.output).write_text(f"Measured {stamp} on {machine_description()}; "
                                         f"`{command}`.\n\n{table}")
    return 0 if all(matches(case.expected, out.measured) or out.measured == "not run"
                    for case, out in results) else 1
