"""Plots of a run's ``stats.csv`` (matplotlib, Agg backend): energies and solver effort.

* ``energies.png``: kinetic, elastic, gravitational and total energy over time. The total
  is what the integrator conserves or dissipates (implicit Euler loses energy; implicit
  Newmark, seed section 3.1 eq. 1, keeps it up to the Newton tolerance).
* ``newton.png``: Newton iterations (top) and linear solver iterations (bottom) per
  accepted step; steps that needed retries with a smaller dt are marked, and substeps
  (dt smaller than the frame step) drawn in another colour.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from fem_anim.errors import FemAnimError

__all__ = ["read_stats", "write_plots", "PLOT_COLUMNS"]

#: The ``stats.csv`` columns the plots use (:data:`fem_anim.output.files.STATS_COLUMNS`
#: has them all).
PLOT_COLUMNS = ("step", "time", "dt", "retries", "newton_its", "linear_its", "kinetic",
                "elastic", "gravity", "total_energy")


def read_stats(path: Path) -> dict[str, np.ndarray]:
    """The plotted columns of ``stats.csv`` as float arrays.

    Args:
        path: The ``stats.csv`` file.

    Returns:
        :data:`PLOT_COLUMNS` name -> one value per row.

    Raises:
        FemAnimError: if the file is missing a column, has no rows or a non-number.
    """
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise FemAnimError(f"{path} cannot be read: {err}") from None
    if not rows:
        raise FemAnimError(f"{path} has no steps")
    missing = [c for c in PLOT_COLUMNS if c not in rows[0]]
    if missing:
        raise FemAnimError(f"{path} has no column {missing[0]}")
    try:
        return {c: np.array([float(row[c]) for row in rows]) for c in PLOT_COLUMNS}
    except (TypeError, ValueError) as err:
        raise FemAnimError(f"{path}: a value is not a number ({err})") from None


def write_plots(stats_csv: Path, directory: Path, dpi: int = 100) -> list[Path]:
    """Plot a run's statistics.

    Args:
        stats_csv: The run's ``stats.csv``.
        directory: Where to write ``energies.png`` and ``newton.png``.
        dpi: Resolution of the PNG files.

    Returns:
        The paths of the two files.

    Raises:
        FemAnimError: if ``stats_csv`` lacks a column or holds a non-number.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = read_stats(stats_csv)
    t = s["time"]
    out = [Path(directory) / "energies.png", Path(directory) / "newton.png"]

    fig, ax = plt.subplots(figsize=(6.4, 4.0), layout="constrained")
    for key, label, style in (("kinetic", "kinetic", "-"), ("elastic", "elastic", "-"),
                              ("gravity", "gravity", "-"), ("total_energy", "total", "k--")):
        ax.plot(t, s[key], style, label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("energy (J)")
    ax.set_title(f"Energies (total drift {s['total_energy'][-1] - s['total_energy'][0]:+.3g} J"
                 " over the run)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.savefig(out[0], dpi=dpi)
    plt.close(fig)

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 4.8), sharex=True,
                                      layout="constrained")
    substep = s["dt"] < (1.0 - 1e-9) * s["dt"].max()
    retried = s["retries"] > 0
    for ax, key, label in ((top, "newton_its", "Newton iterations"),
                           (bottom, "linear_its", "linear iterations")):
        ax.step(t, s[key], where="mid", color="C0", label="step")
        if substep.any():
            ax.plot(t[substep], s[key][substep], "o", color="C1", ms=3, label="substep")
        if retried.any():
            ax.plot(t[retried], s[key][retried], "x", color="C3", ms=7,
                    label="after a retry with dt halved")
        ax.set_ylabel(label)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    top.set_title(f"Solver effort: {int(s['newton_its'].sum())} Newton and "
                  f"{int(s['linear_its'].sum())} linear iterations in {t.size} accepted steps")
    if substep.any() or retried.any():
        top.legend(fontsize="small")
    bottom.set_xlabel("time (s)")
    fig.savefig(out[1], dpi=dpi)
    plt.close(fig)
    return out
