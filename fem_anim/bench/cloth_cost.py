"""What a step of a sheet draped over a ball costs, beside a solid of as many vertices, in one run.

    python -m fem_anim.bench.cloth_cost [--vertices N,N,...] [--steps N] [--out DIR]

For each vertex count N (default 2 500 and 10 000), one after the other in one process:

* **cloth, exact**: the drape demo's scene (``demos/drape.toml``: a 0.6 m square of cloth,
  t = 1 mm, StVK E = 1 MPa, derived hinge bending, 0.3 kg/m^2; the ball and the ground as
  obstacles with friction 0.4, IPC self contact with the thickness as offset and friction
  0.3; implicit Euler, dt = 0.01 s) with ``mesh.element_size = 0.6 / (sqrt(N) - 1)`` and
  the sheet started 2 mm above the ball's top, so that contact acts from the first step;
* **cloth, one Newton step**: the same with the keys ``solver.mode = "preview"`` fills for a
  scene without contact (``max_iterations = 1``, ``on_budget = "accept"``, ``cg-icc`` to a
  relative residual of 1e-4) set by hand: the mode itself leaves contact scenes exact
  (:mod:`fem_anim.scene.modes`); its error is the largest vertex distance from the exact
  run's position at the end time, over the exact run's largest displacement;
* **solid, exact**: the default scene (``fem_anim/default_scene.toml``, a hanging
  neo-Hookean beam, Newmark) with the element size that gives about N vertices.

Each case's time per time step (of the scene's dt) is the sum of ``stats.csv``'s
``step_wall_s`` over its rows (the accepted substeps; the first step, which pays for the
matrix's pattern, included) over the number of time steps, split by the sums of its
columns: ``assembly_s`` (the UFL forms' residuals, Hessians and objectives, and ipctk's
barrier inside them), ``contact_s`` (all ipctk time: detection, barrier, continuous
collision detection: part of the assembly and of the rest), ``factor_s +
linear_solve_s`` and the rest; Newton iterations per time step from ``newton_its``. A
substep that failed and was retried at half dt is in no row (its time is not in these
columns). Then one Hessian and one gradient assembly of the membrane alone, the
bending alone and the step's whole UFL Hessian (with mass and obstacles) are timed on the
cloth's mesh (the fastest of five), to split the assembly between the two energies.

Writes ``cloth_cost.md`` (the table) and ``cloth_cost.json`` (every number) to ``--out``
(default ``demos/results/cloth_cost``). Timings on a shared machine vary with its load:
compare the rows of one run, not runs of different days.
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fem_anim.errors import FemAnimError
from fem_anim.output.products import check_may_write, write_product

__all__ = ["CASES", "VERTICES", "cloth_scene", "cost_table", "form_split", "main",
           "solid_scene", "step_costs"]

VERTICES = (2500, 10000)
CASES = ("cloth, exact", "cloth, one Newton step", "solid, exact")
ROOT = Path(__file__).resolve().parents[2]
#: The keys of ``solver.mode = "preview"`` (:data:`fem_anim.scene.modes.SOLVER_MODES`)
#: without ``hessian`` (a shell keeps its exact Hessian).
ONE_STEP = {"max_iterations": 1, "on_budget": "accept", "preset": "cg-icc",
            "petsc": {"ksp_rtol": 1e-4}}


def cloth_scene(vertices: int, steps: int, one_step: bool = False):
    """The drape demo's scene with about ``vertices`` vertices, started at the ball.

    Args:
        vertices: The target vertex count N (the sheet has (round(sqrt N))^2).
        steps: Time steps.
        one_step: Set the preview's keys (:data:`ONE_STEP`).
    """
    import tomllib

    from fem_anim import Scene

    raw = tomllib.loads((ROOT / "demos" / "drape.toml").read_text())
    n = round(math.sqrt(vertices)) - 1
    raw["mesh"]["element_size"] = 0.6 / n
    raw["mesh"]["origin"][2] = 0.24 + 0.002  # 2 mm above the ball's top (0.24 m)
    raw["time"]["steps"] = steps
    raw["output"] = {"render": False, "fps": 1.0 / raw["time"]["dt"]}
    if one_step:
        raw["solver"] = dict(ONE_STEP)
    return Scene.from_dict(raw, base_dir=ROOT / "demos")


def solid_scene(vertices: int, steps: int):
    """The default scene (a 1 x 0.2 x 0.2 m beam) meshed for about ``vertices`` vertices:
    element size h with (1 / h + 1) (0.2 / h + 1)^2 = N."""
    import tomllib

    from scipy.optimize import brentq

    from fem_anim import Scene

    raw = tomllib.loads((ROOT / "fem_anim" / "default_scene.toml").read_text())
    h = brentq(lambda h: (1 / h + 1) * (0.2 / h + 1) ** 2 - vertices, 1e-3, 0.2)
    raw["mesh"]["element_size"] = h
    raw["time"]["steps"] = steps
    raw["output"] = {"render": False, "fps": 1.0 / raw["time"]["dt"]}
    return Scene.from_dict(raw, base_dir=ROOT)


def step_costs(scene, out: Path) -> dict:
    """Run ``scene`` and take its cost per time step (of the scene's dt) from its files.

    Returns:
        ``vertices``, ``cells``, ``steps`` (time steps), ``substeps`` (accepted ones:
        ``stats.csv``'s rows; the adaptive stepper halves dt after a failed try) and
        ``retries``; per time step, summed over the rows: ``step_s`` (their
        ``step_wall_s``), ``assembly_s``, ``contact_s``, ``solve_s`` (factor + linear
        solve), ``other_s`` and ``newton_its``; ``newton_its_max`` of one row, the largest
        contact pair count, the run's wall seconds and the final displacement (``u``, not
        written to JSON).
    """
    import fem_anim

    start = time.perf_counter()
    with fem_anim.run(scene, out) as run:
        rows = run.stats
        u = run.displacement(len(run.times) - 1)
        points, cells = run.points, run.cells
        retries = int(run.summary["retries"])
    wall = time.perf_counter() - start
    steps = int(scene["time"]["steps"])

    def per_step(key):
        return float(np.sum([float(r[key]) for r in rows])) / steps
    its = [int(r["newton_its"]) for r in rows]
    return {"vertices": len(points), "cells": len(cells), "steps": steps,
            "substeps": len(rows), "retries": retries,
            "step_s": per_step("step_wall_s"), "assembly_s": per_step("assembly_s"),
            "contact_s": per_step("contact_s"),
            "solve_s": per_step("factor_s") + per_step("linear_solve_s"),
            "other_s": per_step("other_s"), "newton_its": per_step("newton_its"),
            "newton_its_max": max(its),
            "pairs_max": max(int(r["contact_pairs"]) for r in rows), "run_s": wall, "u": u}


def form_split(scene, repeats: int = 5) -> dict:
    """Seconds of one Hessian plus one gradient assembly of the membrane alone, the bending
    alone and the step's whole UFL Hessian and gradient (the fastest of ``repeats``), on the
    scene's mesh at rest (P1 kernels cost the same at every state)."""
    import ufl
    from dolfinx.fem import petsc as fem_petsc
    from mpi4py import MPI

    from fem_anim.problem.form_compiler import compile_forms
    from fem_anim.simulation.loop import Simulation

    p = Simulation(scene, MPI.COMM_WORLD).problem
    v, w = ufl.TestFunction(p.V), ufl.TrialFunction(p.V)
    energies = {"membrane": p.shell.membrane(p.u, p.dx_shell),
                "bending": p.shell.bending_energy(p.u, p.dS_shell)}
    forms = {}
    for name, E in energies.items():
        grad = ufl.derivative(E, p.u, v)
        forms[name + "_hessian"] = ufl.derivative(grad, p.u, w)
        forms[name + "_gradient"] = grad
    compiled = compile_forms(forms)
    compiled["step_hessian"] = p.jacobian_form
    compiled["step_gradient"] = p.residual_form
    seconds = {}
    for name in ("membrane", "bending", "step"):
        H, g = compiled[name + "_hessian"], compiled[name + "_gradient"]
        A, b = fem_petsc.create_matrix(H), fem_petsc.create_vector(g)
        best = math.inf
        for _ in range(repeats):
            start = time.perf_counter()
            A.zeroEntries()
            fem_petsc.assemble_matrix(A, H)
            A.assemble()
            with b.localForm() as local:
                local.set(0.0)
            fem_petsc.assemble_vector(b, g)
            best = min(best, time.perf_counter() - start)
        seconds[name + "_s"] = best
        A.destroy()
        b.destroy()
    return seconds


def cost_table(out: Path, vertices=VERTICES, steps: int = 6) -> str:
    """Run every case at every size, write ``cloth_cost.md`` and ``cloth_cost.json`` to
    ``out`` and return the table."""
    results = []
    with tempfile.TemporaryDirectory(prefix="fem_anim_cloth_cost_") as tmp:
        for n in vertices:
            exact = step_costs(cloth_scene(n, steps), Path(tmp) / f"exact_{n}")
            one = step_costs(cloth_scene(n, steps, one_step=True), Path(tmp) / f"one_{n}")
            solid = step_costs(solid_scene(n, steps), Path(tmp) / f"solid_{n}")
            scale = float(np.max(np.linalg.norm(exact["u"], axis=1)))
            one["error"] = float(np.max(np.linalg.norm(one["u"] - exact["u"], axis=1))) / scale
            split = form_split(cloth_scene(n, steps))
            for label, row in zip(CASES, (exact, one, solid)):
                row.pop("u")
                results.append({"case": label, "target_vertices": n, **row,
                                **({"forms": split} if row is exact else {})})
            print(f"{n}: done", flush=True)
    lines = [f"Cloth drape (exact, one Newton step) and the default solid, {steps} time steps "
             "each, one process, one after the other; seconds per time step", "",
             "| case | vertices | cells | s/step | assembly | ipctk | factor + solve | other "
             "| substeps (retries) | Newton its/step (max) | us/step/vertex "
             "| end error |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        error = f"{r['error']:.2e}" if "error" in r else ""
        lines.append(
            f"| {r['case']} | {r['vertices']} | {r['cells']} | {r['step_s']:.3f} | "
            f"{r['assembly_s']:.3f} | {r['contact_s']:.3f} | {r['solve_s']:.3f} | "
            f"{r['other_s']:.3f} | {r['substeps']} "
            f"({r['retries']}) | {r['newton_its']:.1f} ({r['newton_its_max']}) | "
            f"{1e6 * r['step_s'] / r['vertices']:.0f} | {error} |")
    lines += ["", "One Hessian + gradient assembly on the cloth's mesh (fastest of 5):", "",
              "| vertices | membrane (s) | bending (s) | whole step's UFL forms (s) |",
              "|---|---|---|---|"]
    for r in results:
        if "forms" in r:
            f = r["forms"]
            lines.append(f"| {r['vertices']} | {f['membrane_s']:.4f} | {f['bending_s']:.4f} | "
                         f"{f['step_s']:.4f} |")
    table = "\n".join(lines) + "\n"
    write_product(out / "cloth_cost.json", json.dumps(results, indent=1).encode())
    write_product(out / "cloth_cost.md", table.encode())
    return table


def main(argv: list[str] | None = None) -> int:
    from fem_anim.console import OneLineParser, exit_status
    from fem_anim.petsc_options import init_petsc

    init_petsc([])
    p = OneLineParser(prog="python -m fem_anim.bench.cloth_cost",
                      description=__doc__.split("\n")[0])
    p.add_argument("--vertices", default=",".join(map(str, VERTICES)),
                   help="vertex counts, N,N,... (each at least 100)")
    p.add_argument("--steps", type=int, default=6)
    p.add_argument("--out", default="demos/results/cloth_cost")
    args = None

    def run() -> int:
        nonlocal args
        args = p.parse_args(list(sys.argv[1:] if argv is None else argv))
        try:
            vertices = tuple(int(v) for v in args.vertices.split(","))
        except ValueError:
            raise FemAnimError("--vertices takes whole numbers separated by commas, got "
                               f"{args.vertices!r}") from None
        if min(vertices) < 100 or not 2 <= args.steps <= 1000:
            raise FemAnimError(f"--vertices must be at least 100 and --steps between 2 and "
                               f"1000, got {args.vertices!r} and {args.steps}")
        out = Path(args.out)
        check_may_write(out, ["cloth_cost.md", "cloth_cost.json"])
        print(cost_table(out, vertices, args.steps))
        return 0

    return exit_status(run, lambda: args.out)


if __name__ == "__main__":
    sys.exit(main())
