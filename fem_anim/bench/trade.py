"""``fem-anim bench SCENE.toml``: the speed-accuracy trade study of one scene.

    fem-anim bench [SCENE.toml] [--sweep KEY=V1,V2,...]... [--repeats N]
                   [--reference KEY=V]... [--set KEY=V]... [--probe X,Y[,Z]] [-o OUTDIR]

Every configuration of the swept knobs (:mod:`fem_anim.bench.sweep`) is built, run
``--repeats`` times and measured (:mod:`fem_anim.bench.measure`): wall time per
simulated second (median of the repeats; mesh generation and form compilation reported
separately), Newton and linear iterations, retries of the adaptive stepper, energy drift
(:mod:`fem_anim.simulation.energy_report`), and the error against a fine reference run of the
same scene:

    e_L2 = sqrt( sum_k sum_p |u(p, t_k) - u_ref(p, t_k)|^2 / sum_k sum_p |u_ref(p, t_k)|^2 )

over the comparison times t_k = k H and the sample points p (the reference mesh's
vertices, evaluated in each configuration's own mesh), and at the probe point
(default: the sample point that moves furthest in the reference)
e_probe = max_k |u(p*, t_k) - u_ref(p*, t_k)| / max_k |u_ref(p*, t_k)|.
Outputs in OUTDIR (default ``out/<scene>_trade``): ``trade_study.csv``,
``trade_study.png`` (:func:`fem_anim.bench.pareto.plot_pareto`) and ``trade_study.md``
(the Pareto-optimal configurations: for this accuracy, use this). OUTDIR may hold other
files, but not files of these names that fem_anim did not write (refused before the study
starts, :func:`fem_anim.output.products.check_may_write`); the three are written together
when the study ends, so an interrupted study leaves the previous ones as they were.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
from pathlib import Path

import numpy as np

from fem_anim.console import OneLineParser
from fem_anim.errors import FemAnimError, SceneError, describe_os_error
from fem_anim.output.products import check_may_write, staged_products
from fem_anim.bench.sweep import expand_study

__all__ = ["main", "build_parser", "trajectory_errors", "machine_description", "COLUMNS",
           "PRODUCTS"]

#: The files a trade study writes into its output directory.
PRODUCTS = ("trade_study.csv", "trade_study.png", "trade_study.md")

COLUMNS = ["label", "status", "dofs", "steps", "retries", "newton_its", "linear_its",
           "mesh_s", "compile_s", "first_run_s", "wall_median_s", "wall_per_sim_s",
           "error_l2", "error_probe", "energy_drift", "energy_excursion", "damped"]


class _Parser(OneLineParser):
    prefix = "bench: "


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="fem-anim bench", description=__doc__.split("\n")[0])
    p.add_argument("scene", nargs="?", help="scene TOML file (default: the hanging beam)")
    p.add_argument("--sweep", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="a scene key and its values (repeat for a Cartesian product)")
    p.add_argument("--repeats", type=int, default=3, help="timed runs per configuration")
    p.add_argument("--reference", action="append", default=[], metavar="KEY=V",
                   help="override a key of the reference run")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=V",
                   help="override a key of the base scene (all runs)")
    p.add_argument("--probe", help="probe point X,Y[,Z] (default: the furthest-moving point)")
    p.add_argument("-o", "--output", help="output directory (default out/<scene>_trade)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    return p


def trajectory_errors(u: np.ndarray, ref: np.ndarray, probe: int) -> tuple[float, float]:
    """Relative L2 error over (times, points) and relative max error at point ``probe``.

    Points where either trajectory is NaN (outside one of the meshes) are left out.
    """
    keep = np.all(np.isfinite(u), axis=(0, 2)) & np.all(np.isfinite(ref), axis=(0, 2))
    diff = u[:, keep] - ref[:, keep]
    e_l2 = float(np.sqrt(np.sum(diff ** 2) / np.sum(ref[:, keep] ** 2)))
    dp = np.linalg.norm(u[:, probe] - ref[:, probe], axis=1)
    e_probe = float(np.max(dp) / np.max(np.linalg.norm(ref[:, probe], axis=1)))
    return e_l2, e_probe


def machine_description() -> str:
    """CPU model, core count and load average of this machine."""
    model = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return f"{model}, {os.cpu_count()} cores, load average {load}"


def _say(comm, quiet, text):
    if comm.rank == 0 and not quiet:
        print(text, flush=True)


def _study(args) -> int:
    from mpi4py import MPI

    study = expand_study(args.scene, args.overrides, args.sweep, args.reference)
    study.argv = args.argv
    if args.repeats < 1:
        raise FemAnimError(f"bench: --repeats must be >= 1, got {args.repeats}")
    probe_xyz = None
    if args.probe:
        try:
            probe_xyz = np.array([float(c) for c in args.probe.split(",")])
        except ValueError:
            raise FemAnimError(f"bench: --probe must be X,Y[,Z], got {args.probe!r}") from None
        if probe_xyz.size != study.base.dim or not np.all(np.isfinite(probe_xyz)):
            raise FemAnimError(f"bench: --probe needs {study.base.dim} finite coordinates, "
                               f"got {args.probe!r}")
    out = Path(args.output or f"out/{study.base.name}_trade")
    comm = MPI.COMM_WORLD
    error = None
    if comm.rank == 0:
        try:
            check_may_write(out, PRODUCTS)
            out.mkdir(parents=True, exist_ok=True)
        except FemAnimError as err:
            error = f"bench: {err}"
        except OSError as err:
            error = f"bench: output directory {out} cannot be written: " \
                    f"{describe_os_error(err, out)}"
    if (error := comm.bcast(error, root=0)):
        raise FemAnimError(error)

    from fem_anim.console import quiet_jit_logging
    from fem_anim.mesh.bodies import build_scene_mesh
    from fem_anim.bench.measure import measure_configuration, median_run

    quiet_jit_logging()
    ref_scene = study.reference.scene
    domain = build_scene_mesh(comm, ref_scene)
    points = comm.bcast(domain.points if comm.rank == 0 else None, root=0)
    stride = round(study.interval / ref_scene["time"]["dt"])
    _say(comm, args.quiet, f"bench: reference ({' '.join(study.reference.overrides)}), "
         f"{points.shape[0]} sample points, {study.frames} comparison times")
    ref = measure_configuration(ref_scene, comm, points, stride, 1, domain=domain)
    if ref.status != "ok":
        raise FemAnimError(f"bench: the reference run failed ({ref.status}); choose another "
                           "with --reference")
    if probe_xyz is not None:
        probe = int(np.argmin(np.linalg.norm(points - probe_xyz, axis=1)))
    else:
        probe = int(np.nanargmax(np.nanmax(np.linalg.norm(ref.samples, axis=2), axis=0)))
    keys = list(study.configurations[0].values) if study.configurations else []
    rows = []
    for n, config in enumerate(study.configurations, 1):
        row = {"label": config.label, **config.values}
        if config.scene is None:
            rows.append(row | {"status": f"skipped: {config.skipped}"})
            _say(comm, args.quiet, f"bench: [{n}/{len(study.configurations)}] {config.label}: "
                 f"skipped ({config.skipped})")
            continue
        stride = round(study.interval / config.scene["time"]["dt"])
        m = measure_configuration(config.scene, comm, points, stride, args.repeats)
        row |= {"status": m.status, "dofs": m.dofs, "mesh_s": m.mesh_s,
                "compile_s": m.compile_s}
        if m.status == "ok":
            e_l2, e_probe = trajectory_errors(m.samples, ref.samples, probe)
            wall = median_run(m)
            row |= {"steps": m.steps, "retries": m.retries, "newton_its": m.newton_its,
                    "linear_its": m.linear_its, "first_run_s": m.run_s[0],
                    "wall_median_s": wall, "wall_per_sim_s": wall / study.duration,
                    "error_l2": e_l2, "error_probe": e_probe,
                    "energy_drift": m.energy["drift"],
                    "energy_excursion": m.energy["max_excursion"],
                    "damped": m.energy["damped"]}
        rows.append(row)
        _say(comm, args.quiet, f"bench: [{n}/{len(study.configurations)}] {config.label}: "
             + (f"{row['wall_per_sim_s']:.3g} s/s, error {row['error_l2']:.3g}, "
                f"compile {m.compile_s:.2f} s" if m.status == "ok" else m.status))
    if comm.rank == 0:
        try:
            with staged_products(out, PRODUCTS) as staging:
                _write_outputs(staging, study, rows, keys, points, probe, ref)
        except OSError as err:
            raise FemAnimError(f"bench: the results cannot be written into {out}: "
                               f"{describe_os_error(err, out)}; nothing was replaced") from None
        _say(comm, args.quiet, (out / "trade_study.md").read_text())
    return 0


def _write_outputs(out, study, rows, keys, points, probe, ref) -> None:
    from fem_anim.bench.pareto import pareto_front, pareto_table, plot_pareto, short, write_csv

    cost = [r.get("wall_per_sim_s", np.nan) for r in rows]
    err = [r.get("error_l2", np.nan) for r in rows]
    front = pareto_front(cost, err)
    for r, on in zip(rows, front):
        r["pareto"] = bool(on)
    write_csv(out / "trade_study.csv", rows, ["label", *keys, *COLUMNS[1:], "pareto"])
    ok = [i for i, r in enumerate(rows) if r["status"] == "ok"]
    reference = " ".join(f"{o.split('=', 1)[0].split('.')[-1]}={short(o.split('=', 1)[1])}"
                         for o in study.reference.overrides)
    title = (f"{study.base.name}: {len(ok)} configurations, {study.duration:.3g} s simulated "
             f"each\nerror against the reference run ({reference})")
    if ok:
        plot_pareto(out / "trade_study.png", [rows[i] for i in ok], front[ok], title, keys)
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    failed = [r for r in rows if r["status"] != "ok"]
    text = [f"# Trade study: {study.base.name}", "",
            f"Measured {stamp} on {machine_description()}.", "",
            f"Command: `fem-anim bench {' '.join(study.argv)}`",
            "",
            f"{len(rows)} configurations, {study.duration:.4g} s simulated each, compared at "
            f"{study.frames} times (every {study.interval:.4g} s) at {points.shape[0]} points "
            f"against the reference `{' '.join(study.reference.overrides)}` "
            f"({ref.dofs} dofs, {ref.newton_its} Newton iterations); probe point "
            f"{np.array2string(points[probe], precision=3)}.",
            "", "Pareto-optimal configurations, least accurate first:", "",
            pareto_table(rows, front, keys)]
    reasons: dict[str, list[str]] = {}
    for r in failed:  # one line per distinct reason (a forbidden combination repeats)
        reason = r["status"].split(": ", 1)[0] + ": " + r["status"].split(": ")[-1]
        reasons.setdefault(reason, []).append(r["label"])
    if reasons:
        text += ["Not on the plot:", ""] + [f"- {len(labels)} configuration(s) {reason} "
                                            f"({'; '.join(labels)})"
                                            for reason, labels in reasons.items()]
    (out / "trade_study.md").write_text("\n".join(text) + "\n")


def main(argv: list[str]) -> int:
    """Run the trade study; returns the exit code (2 and one line for bad input)."""
    from fem_anim.console import print_error

    try:
        args = build_parser().parse_args(argv)
        args.argv = list(argv)
        return _study(args)
    except (FemAnimError, SceneError) as err:
        print_error(str(err))
        return 2
