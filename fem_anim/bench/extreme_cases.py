"""The hard scenes of the extremes bench and what each must do, derived from its scene.

Each :class:`Case` is a scene pushed to an extreme (Young's modulus 1e2 to 1e9 Pa,
Poisson ratio up to 0.4999, dt from 1e-5 to 1 s, a spinning body, a stretched and a
fully compressed bar, elements of aspect ratio 50 and more, a press that inverts
elements in one step): :func:`cases`. Its expected outcome is derived from the scene by
:func:`expected_outcome` (the maths is there), not copied from a run:

- :data:`FINISHES`: the continuous problem is well posed, the run must complete, either
  ``converges-bounded`` (every step converges at once) or ``recovers-by-substepping``
  (some steps fail, the adaptive stepper halves dt and the run completes,
  :class:`fem_anim.simulation.adaptive.AdaptiveStepper`); which of the two is solver behaviour,
  reported but not expected;
- ``recovers-by-substepping``: the first step's pin motion alone inverts a layer of
  elements, the full step cannot start, a smaller one can;
- ``stops-with-message``: the pins close the body's thickness to zero: no admissible
  state, the run stops with a :class:`~fem_anim.errors.ConvergenceError`;
- ``fails the physical check``: the linear material on a spinning body (seed eq. 36).

A completed run must also be *bounded* (:data:`ENERGY_GROWTH_BOUND`), and a case may add its
own check: the spinning body keeps its volume after half a turn; the stiffest beam never
deflects beyond :func:`sag_bound`. Running the cases is :mod:`fem_anim.bench.extremes`.
"""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fem_anim.scene.loading import load_scene

__all__ = ["Case", "cases", "beam_scene", "scene_text", "load_case_scene", "OUTCOMES",
           "COMPLETED", "ENERGY_GROWTH_BOUND", "FINISHES", "sag_bound", "expected_outcome",
           "matches", "pin_displacement", "pinned_gaps"]

OUTCOMES = ("converges-bounded", "recovers-by-substepping", "stops-with-message")

#: Measured outcomes of a run that reached its last step (the linear spinning body does, and
#: then fails the check its physics predicts).
COMPLETED = ("converges-bounded", "recovers-by-substepping", "fails the physical check")

#: Largest rise of the total energy above E_0 in a conservative scene, as a fraction of the
#: exchanged energy (:func:`fem_anim.simulation.energy_report.energy_report`: the largest of
#: |E_0|, the kinetic energy and the drop of the potential energy over the run). The continuous
#: system conserves E (kinetic K plus potential P); implicit Euler's step satisfies
#: M (v_{n+1} - v_n) = -h grad P(x_{n+1}), and for a P convex along the step this gives
#: K_{n+1} + P_{n+1} + 1/2 ||v_{n+1} - v_n||_M^2 <= K_n + P_n (it only loses energy);
#: Newmark (the trapezoidal rule) conserves E exactly for a quadratic energy, and a
#: nonlinear one changes it by O(dt^2) relative to the strain energy's nonlinear part,
#: small at the strains of these cases; the Newton tolerance adds |r| |dx| per step
#: (round-off level at rtol 1e-8). A rise of 1 % is none of these: it is a scheme or a
#: term that creates energy.
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


def beam_scene(dim: int, full: bool, size=None, es=None, gravity=True, **sections) -> dict:
    """The scene dictionary of a cantilever pinned at x = 0: 1 x 0.2 (x 0.2) m, E = 1e5 Pa.

    Args:
        dim: 2 or 3.
        full: Element size 0.05 m (the full grid) instead of 0.1 m, unless ``es`` is given.
        size: The box's size (m), default the beam's.
        es: Element size (m).
        gravity: Whether gravity (-9.81 m/s^2 along the last axis) acts.
        **sections: Scene tables merged into (a dict) or replacing (a list) the defaults.

    Returns:
        A scene dictionary for :func:`scene_text` / :func:`load_case_scene`.
    """
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
        out.append(Case(f"E = {E:.0e} Pa", beam_scene(d, full, material={"youngs_modulus": E}),
                        "", (15 if E <= 1e2 else 6) * n,
                        check="sag" if E >= 1e9 else ""))
    for nu in ([0.45, 0.49, 0.4999] if full else [0.4999]):
        if nu == 0.4999:  # the Taylor-Hood (u, p) formulation where P1 and P2 struggle
            out.append(Case(f"nu = {nu}, P2/P1 mixed", beam_scene(
                d, full, material={"poisson_ratio": nu}, solver={"preset": "ldlt"},
                element={"degree": 2, "formulation": "mixed"},
                time={"dt": 1.0 / 30.0, "min_dt": 1.0 / 480.0}), "", 4 * n))
        for p in (1, 2):
            # the floor of adaptive halving at dt/16: a stalled 3D P2 run stops in a minute
            out.append(Case(f"nu = {nu}, P{p}", beam_scene(
                d, full, material={"poisson_ratio": nu}, element={"degree": p},
                time={"dt": 1.0 / 30.0, "min_dt": 1.0 / 480.0}),
                "", 4 * n))
    for dt in ([1e-5, 1e-3, 1e-1, 1.0] if full else [1e-5, 1.0]):
        out.append(Case(f"dt = {dt:g} s", beam_scene(d, full, time={"dt": dt}),
                        "", 3 * n))
    axis = {"axis": [0.0, 0.0, 1.0]} if d == 3 else {}
    centre = [0.5, 0.1, 0.1][:d]
    hub = {"name": "hub", "min": [0.4] + [0.0] * (d - 1), "max": [0.6] + [0.2] * (d - 1),
           "angular_velocity": math.pi, "center": centre, **axis}
    for model in ("neohookean", "linear"):
        out.append(Case(f"spinning body (half a turn in 1 s), {model}", beam_scene(
            d, full, gravity=False, pin=[hub], material={"youngs_modulus": 1e7, "model": model},
            time={"dt": 1.0 / 30.0}), "", 30, check="rigid"))
    right = {"name": "end", "min": [1.0 - 1e-6] + [-10.0] * (d - 1),
             "max": [1.0 + 1e-6] + [10.0] * (d - 1)}
    wall = beam_scene(d, full)["pin"][0]
    out.append(Case("stretched to 3x length", beam_scene(
        d, full, gravity=False, time={"dt": 0.1},
        pin=[wall, right | {"velocity": [2.0] + [0.0] * (d - 1), "until": 1.0}]),
        "", 10))
    floor = {"name": "floor", "min": [-10.0] * (d - 1) + [-1e-6],
             "max": [10.0] * (d - 1) + [1e-6]}
    press = {"name": "press", "min": [-10.0] * (d - 1) + [0.2 - 1e-6],
             "max": [10.0] * (d - 1) + [0.2 + 1e-6]}
    out.append(Case("crushed to zero thickness", beam_scene(
        d, full, gravity=False, time={"dt": 0.1},
        pin=[floor, press | {"velocity": [0.0] * (d - 1) + [-0.2], "until": 1.0}]),
        "", 10))
    out.append(Case("press inverts elements in one step", beam_scene(
        d, full, gravity=False, time={"dt": 0.1},
        pin=[wall, right | {"velocity": [-4.0] + [0.0] * (d - 1), "until": 0.1}]),
        "", 3))
    thin = [2.0, 0.02, 0.02][:d]
    out.append(Case("thin elements (aspect >= 50)", beam_scene(
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


def load_case_scene(data: dict, overrides: list[str] = ()):
    """Validate a scene dictionary exactly as a file, with ``--set KEY=VALUE`` overrides.

    The dictionary is written as TOML (:func:`scene_text`) to a temporary file and loaded
    by :func:`fem_anim.scene.loading.load_scene` (each rank reads its own copy).

    Returns:
        The validated scene.

    Raises:
        SceneError: as for a scene file with a bad key or value.
    """
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "case.toml"
        path.write_text(scene_text(data))
        return load_scene(path, list(overrides))
