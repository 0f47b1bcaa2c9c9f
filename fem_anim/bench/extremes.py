"""Running the extremes bench: each hard scene's outcome, the locking study, the table.

    fem-anim bench --extremes [--full] [--set KEY=VALUE ...] [--no-locking] [-o TABLE.md]

:func:`run_case` runs a case of :func:`fem_anim.bench.extreme_cases.cases` to its end or its
error and classifies what happened (its expected outcome is
:func:`fem_anim.bench.extreme_cases.expected_outcome`). A completed run is *bounded* when, in
a conservative scene (no damping, no moving pins), the total energy never exceeds its initial
value E_0 by more than :data:`~fem_anim.bench.extreme_cases.ENERGY_GROWTH_BOUND` times the
exchanged energy (:mod:`fem_anim.simulation.energy_report`); with moving pins (which do work
on the body) it must stay finite. :func:`locking_rows` and :func:`mixed_locking_rows` measure
what volumetric locking does to P1, P2 and the mixed P2/P1 formulation near nu = 0.5
(quasi-static tip deflection under gravity); :func:`format_table` writes both as markdown.
The fast variants (2D, coarse, few steps) run in CI; ``--full`` runs the 3D grid.
"""

from __future__ import annotations

import argparse
import datetime
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fem_anim.bench.extreme_cases import (COMPLETED, ENERGY_GROWTH_BOUND, Case, beam_scene, cases,
                                          load_case_scene, matches, sag_bound)
from fem_anim.errors import ConvergenceError, FemAnimError, SceneError, describe_os_error
from fem_anim.mesh.checks import cell_volumes
from fem_anim.output.products import check_may_write, write_product

__all__ = ["Outcome", "run_case", "locking_rows", "mixed_locking_rows", "format_table", "main"]


@dataclass
class Outcome:
    """What a case did."""

    measured: str
    detail: str
    seconds: float
    info: dict = field(default_factory=dict)


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
    from fem_anim.simulation.adaptive import AdaptiveStepper
    from fem_anim.simulation.loop import Simulation

    comm = comm or MPI.COMM_WORLD
    data = case.keys | {"time": case.keys["time"] | {"steps": case.steps}}
    scene = load_case_scene(data, overrides)
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
            data = beam_scene(d, full, es=size,
                              material={"youngs_modulus": 1e7, "poisson_ratio": nu},
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
    from fem_anim.simulation.adaptive import AdaptiveStepper
    from fem_anim.simulation.loop import Simulation
    from fem_anim.bench.measure import PointSampler

    scene = load_case_scene(data)
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
            data = beam_scene(d, full, es=size,
                              material={"youngs_modulus": 1e7, "poisson_ratio": nu},
                              element={"degree": 2, "formulation": "mixed"},
                              solver={"preset": "ldlt"},
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
        if args.output:  # before the cases, not after
            check_may_write(Path(args.output).parent, [Path(args.output).name],
                            MPI.COMM_WORLD)
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
            text = f"Measured {stamp} on {machine_description()}; `{command}`.\n\n{table}"
            try:
                write_product(Path(args.output), text.encode())
            except (FemAnimError, OSError) as err:
                message = describe_os_error(err, args.output) \
                    if isinstance(err, OSError) else str(err)
                print_error(f"bench --extremes: {message}")
                return 2
    return 0 if all(matches(case.expected, out.measured) or out.measured == "not run"
                    for case, out in results) else 1
