"""The trade study's outputs: Pareto front, CSV, plot and "for this accuracy, use this" table.

A configuration is Pareto-optimal when no other one is at least as fast *and* at least as
accurate, and strictly better in one of the two. The front, sorted by cost, is a staircase
whose error falls as the cost rises: for a given accuracy target, the cheapest
configuration that reaches it is on the front.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

__all__ = ["pareto_front", "write_csv", "plot_pareto", "pareto_table", "front_labels", "short"]


def pareto_front(cost, error) -> np.ndarray:
    """Boolean mask of the non-dominated points (minimising both); NaN points never are.

    Sorted by cost (then error), a point is on the front when its error is strictly below
    every error seen at a lower or equal cost. Duplicates of a front point keep only the
    first. O(n log n).
    """
    cost, error = np.asarray(cost, float), np.asarray(error, float)
    mask = np.zeros(cost.size, dtype=bool)
    valid = np.flatnonzero(np.isfinite(cost) & np.isfinite(error))
    order = valid[np.lexsort((error[valid], cost[valid]))]
    best = math.inf
    for i in order:  # a loop over configurations (a few dozen), not over cells or dofs
        if error[i] < best:
            mask[i] = True
            best = error[i]
    return mask


def write_csv(path: Path, rows: list[dict], columns: list[str]) -> None:
    """One row per configuration, ``columns`` in order (missing values empty)."""
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _fmt(row.get(k, "")) for k in columns})


def _fmt(v):
    return f"{v:.6g}" if isinstance(v, float) else v


def short(value) -> str:
    """A value for a label or table: numbers to 3 significant digits (1/60 -> 0.0167)."""
    try:
        return f"{float(value):.3g}"
    except (TypeError, ValueError):
        return str(value)


#: Short names of common sweep keys in plot labels (``P2 h=0.1 dt=0.0333 newmark``).
ABBREVIATIONS = {"time.dt": "dt", "mesh.element_size": "h", "element.degree": "P",
                 "element.quadrature_degree": "q", "solver.petsc.snes_rtol": "rtol"}


def _label_part(key: str, value) -> str:
    text = short(value)
    try:
        float(text)
    except ValueError:
        return text  # a word (newmark, lumped, cg-icc) names itself
    name = ABBREVIATIONS.get(key, key.split(".")[-1])
    return f"P{text}" if name == "P" else f"{name}={text}"


def front_labels(rows: list[dict], keys: list[str]) -> list[str]:
    """Labels naming only the swept keys whose values differ between ``rows``."""
    varying = [k for k in keys if len({str(r.get(k)) for r in rows}) > 1] or keys
    return [" ".join(_label_part(k, r.get(k)) for k in varying) for r in rows]


def plot_pareto(path: Path, rows: list[dict], front: np.ndarray, title: str,
                keys: list[str], reference_error: float | None = None) -> None:
    """Log-log error against wall time per simulated second; the front drawn and labelled.

    Front points are labelled with the swept values that differ along the front.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cost = np.array([r["wall_per_sim_s"] for r in rows], float)
    err = np.array([r["error_l2"] for r in rows], float)
    ok = np.isfinite(cost) & np.isfinite(err) & (err > 0)
    fig, ax = plt.subplots(figsize=(12, 6.5), dpi=110)
    fig.subplots_adjust(left=0.085, right=0.63, top=0.9, bottom=0.1)
    ax.scatter(cost[ok & ~front], err[ok & ~front], s=18, c="0.6", label="configuration")
    idx = np.flatnonzero(front & ok)
    idx = idx[np.argsort(cost[idx])]
    ax.step(cost[idx], err[idx], where="post", c="C3", lw=1.2, alpha=0.7)
    ax.scatter(cost[idx], err[idx], s=36, c="C3", zorder=3, label="Pareto front")
    labels = front_labels([rows[i] for i in idx], keys)
    for j, i in enumerate(idx):  # numbers on the plot, the configurations beside it
        ax.annotate(str(j + 1), (cost[i], err[i]), fontsize=8, xytext=(5, 3),
                    textcoords="offset points", color="C3", weight="bold")
    fig.text(0.65, 0.9, "Pareto front (cheapest first)\n" + "\n".join(
        f"{j + 1:2d}  {label}" for j, label in enumerate(labels)), va="top", fontsize=8,
        family="monospace", color="C3")
    if reference_error:
        ax.axhline(reference_error, ls=":", c="0.4", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time per simulated second [s] (median of repeats, forms compiled)")
    ax.set_ylabel("relative L2 displacement error over the trajectory")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(loc="upper right", fontsize=8)
    fig.savefig(path)
    plt.close(fig)


def pareto_table(rows: list[dict], front: np.ndarray, keys: list[str]) -> str:
    """Markdown table of the front, most accurate last: for this accuracy, use this."""
    idx = [i for i in np.flatnonzero(front)]
    idx.sort(key=lambda i: -rows[i]["error_l2"])
    head = ["error (L2, trajectory)", "probe error", "wall s / sim s", *keys, "Newton its",
            "energy drift"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i in idx:
        r = rows[i]
        cells = [f"{r['error_l2']:.2e}", f"{r['error_probe']:.2e}",
                 f"{r['wall_per_sim_s']:.3g}", *[short(r.get(k, "")) for k in keys],
                 str(r["newton_its"]), "at rest" if r["energy_drift"] is None
                 else f"{100 * r['energy_drift']:+.2g} %"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
