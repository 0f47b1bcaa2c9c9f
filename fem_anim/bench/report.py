"""Tables and the plot of :mod:`fem_anim.bench.perf`: ``perf.csv``, ``perf.md``, ``perf.png``.

Also the two comparisons that rerun a configuration with something changed underneath:
reference BLAS/LAPACK against OpenBLAS (the worker's ``LD_LIBRARY_PATH``) and
``mpirun -n 2`` against serial.
"""

from __future__ import annotations

import csv
import datetime
import platform
from pathlib import Path

import numpy as np

from fem_anim.bench.timing import growth_exponent
from fem_anim.bench.worker import PHASE_COLUMNS
from fem_anim.output.products import staged_products

__all__ = ["PRODUCTS", "write", "exponent_text", "blas_rows", "mpi_rows", "machine_text",
           "md_table"]

COLUMNS = ("element_size", "preset", "ranks", "tets", "dofs", "newton_its", "linear_its",
           *PHASE_COLUMNS, "wall", "symbolic_calls", "first_step_s", "setup_s", "peak_mb")


def machine_text(load: str = "?") -> str:
    cpu = "?"
    try:
        for line in open("/proc/cpuinfo", encoding="utf-8"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import os

    return (f"{datetime.date.today().isoformat()}, {cpu}, {os.cpu_count()} cores, "
            f"Python {platform.python_version()}, load average {load} (shared machine)")


def md_table(header: list[str], rows: list[list]) -> str:
    def fmt(v):
        if isinstance(v, float):
            return f"{v:.3g}" if abs(v) < 1e4 else f"{v:.0f}"
        return str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def exponents(rows: list[dict]) -> dict[str, float]:
    """Growth exponent of the step time against dofs, per preset (serial rows)."""
    out = {}
    for preset in dict.fromkeys(r["preset"] for r in rows if r["ranks"] == 1):
        sel = [r for r in rows if r["preset"] == preset and r["ranks"] == 1]
        out[preset] = growth_exponent([r["dofs"] for r in sel], [r["wall"] for r in sel])
    return out


def exponent_text(rows: list[dict]) -> str:
    return "growth exponent of the step time against dofs: " + ", ".join(
        f"{p} {e:.2f}" for p, e in exponents(rows).items())


def split_table(rows: list[dict]) -> str:
    header = ["preset", "tets", "dofs", "Newton", "lin. its", "residual", "Jacobian",
              "objective", "filter", "energies", "factor sym.", "factor num.", "solve",
              "other", "other %", "step s", "peak MiB"]
    body = [[r["preset"], r["tets"], r["dofs"], r["newton_its"], r["linear_its"],
             *(r[c] for c in PHASE_COLUMNS), 100.0 * r["other"] / r["wall"], r["wall"],
             r["peak_mb"]] for r in rows]
    return md_table(header, body)


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    slopes = exponents(rows)
    for preset in slopes:
        sel = sorted((r for r in rows if r["preset"] == preset and r["ranks"] == 1),
                     key=lambda r: r["dofs"])
        ax.loglog([r["dofs"] for r in sel], [r["wall"] for r in sel], "o-",
                  label=f"{preset} (slope {slopes[preset]:.2f})")
    ax.set_xlabel("dofs")
    ax.set_ylabel("wall time per implicit step, s")
    ax.set_title("hanging beam, neo-Hookean, Newton to tolerance")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


#: The files :func:`write` makes in the bench's output folder.
PRODUCTS = ("perf.csv", "perf.md", "perf.png")


def write(out: Path, rows: list[dict], extra: dict, load: str = "?") -> None:
    """Write :data:`PRODUCTS` into ``out``, together, never over a file fem_anim did not write.

    Args:
        out: The output folder (:func:`fem_anim.output.products.staged_products`).
        rows: The sweep's rows.
        extra: The sections' Markdown, by name (empty ones are left out).
        load: The load average to report.

    Raises:
        FemAnimError: if ``out`` holds one of :data:`PRODUCTS` that fem_anim did not write.
        OSError: if ``out`` cannot be written (the old files stay as they were).
    """
    with staged_products(out, PRODUCTS) as staging:
        _write(staging, rows, extra, load)


def _write(out: Path, rows: list[dict], extra: dict, load: str) -> None:
    with open(out / "perf.csv", "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    plot(rows, out / "perf.png")
    text = ["# Performance of one implicit step", "",
            f"Measured {machine_text(load)}. Regenerate: "
            "`python -m fem_anim.bench.perf --mpi --blas --options --hard --peers` "
            "(or `fem-anim bench --perf`).", "",
            "Seconds per step (mean over the timed steps after the first), split by PETSc "
            "log events: residual, Jacobian and objective assembly (the objective is "
            "evaluated by the line search and the convergence test), inversion filter "
            "(det F at the quadrature points), energies for stats.csv, symbolic and numeric "
            "factorisation (PCSetUp: for Krylov presets the preconditioner set-up), "
            "linear solve (KSPSolve), and other = wall - all of them.", "",
            split_table(rows), "", exponent_text(rows) + ".", "",
            "![time per step against dofs](perf.png)", ""]
    for name, section in extra.items():
        if section:
            text += [section, ""]
    (out / "perf.md").write_text("\n".join(text), encoding="utf-8")


def blas_rows(args, petsc, run_config, reference_dirs, repeats: int = 2) -> str:
    """Factorisation time: OpenBLAS (2 threads, 1 thread) against reference BLAS/LAPACK.

    The variants run interleaved, ``repeats`` times each, and the fastest of each is
    reported: on a shared machine the load changes between runs.
    """
    import os

    h = sorted(args.sizes)[len(args.sizes) // 2] if len(args.sizes) > 2 else min(args.sizes)
    preset = args.presets.split(",")[0]
    path = os.environ.get("LD_LIBRARY_PATH", "")
    variants = (("OpenBLAS, pthreads (Debian's libopenblas0-pthread, the default)", {}),
                ("OpenBLAS, OPENBLAS_NUM_THREADS=1", {"OPENBLAS_NUM_THREADS": "1"}),
                ("reference BLAS/LAPACK", {"LD_LIBRARY_PATH": ":".join([*reference_dirs,
                                                                         path])}))
    best: dict[str, dict] = {}
    for _ in range(repeats):
        for name, env in variants:
            r = run_config(args.scene, [*args.overrides, f"mesh.element_size={h}"], preset,
                           args.steps, petsc, env=env)
            if name not in best or r["mean"]["factor_numeric"] < best[name]["mean"][
                    "factor_numeric"]:
                best[name] = r
    body = [[name, r["tets"], r["dofs"], r["mean"]["factor_numeric"], r["mean"]["solve"],
             r["mean"]["wall"]] for name, r in best.items()]
    ref = best[variants[2][0]]["mean"]["factor_numeric"]
    ratios = ", ".join(f"{ref / best[name]['mean']['factor_numeric']:.2f}x for {name}"
                       for name, _ in variants[:2])
    return ("## BLAS\n\n" + md_table(["BLAS", "tets", "dofs", "factor num. s", "solve s",
                                      "step s"], body)
            + f"\n\nNumeric factorisation (preset {preset}, fastest of {repeats} interleaved "
            f"runs each), reference time over: {ratios}. The worker's LD_LIBRARY_PATH puts "
            "Debian's reference libblas.so.3/liblapack.so.3 first; /proc/self/maps confirms "
            "that no OpenBLAS is loaded then.")


def mpi_rows(args, petsc, run_config, serial_rows: list[dict]) -> str:
    """mpirun -n 2 against serial on each preset's largest mesh, ``args.repeats`` pairs.

    Each pair runs back to back (serial, then two ranks), so both see the same machine; the
    table gives the medians over the pairs and every pair's speed-up.
    """
    body = []
    for preset in args.presets.split(","):
        h = min((r for r in serial_rows if r["preset"] == preset),
                key=lambda r: r["element_size"])["element_size"]
        runs: dict[int, list[dict]] = {1: [], 2: []}
        for _ in range(args.repeats):
            for ranks in (1, 2):
                r = run_config(args.scene, [*args.overrides, f"mesh.element_size={h}"],
                               preset, args.steps, petsc, ranks=ranks)
                runs[ranks].append(r | {"mean": r["mean"] | {
                    "assembly": r["mean"]["jacobian"] + r["mean"]["residual"]
                    + r["mean"]["objective"]}})
        speedups = [a["mean"]["wall"] / b["mean"]["wall"] for a, b in zip(runs[1], runs[2])]
        for ranks in (1, 2):
            def median(key, rs=runs[ranks]):
                return float(np.median([r["mean"][key] for r in rs]))

            shown = ", ".join(f"{s:.2f}" for s in speedups) if ranks == 2 else "-"
            body.append([preset, ranks, runs[ranks][0]["tets"], median("newton_its"),
                         median("linear_its"), median("assembly"), median("factor_numeric"),
                         median("solve"), median("other"), median("wall"), shown,
                         float(np.median(speedups)) if ranks == 2 else 1.0])
    return ("## MPI\n\n" + md_table(["preset", "ranks", "tets", "Newton", "lin. its",
                                     "assembly s", "factor num. s", "solve s", "other s",
                                     "step s", "speed-up per pair", "median speed-up"], body)
            + f"\n\nEach preset on its largest mesh: {args.repeats} pairs of runs, serial then "
            "`mpirun -n 2` back to back; medians over the pairs. Under MPI the presets switch "
            "to their parallel variants (MUMPS stays MUMPS; ICC "
            "becomes block Jacobi + ICC per rank).")
