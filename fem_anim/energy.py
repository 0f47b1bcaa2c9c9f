"""Energy behaviour of a run: drift of the total energy and numerical damping.

An undamped scene whose pins do not move conserves the total energy
E = T + Psi + V_gravity exactly in continuous time. Implicit Euler dissipates it
(seed section 3.1: its step objective adds no energy-conserving correction, so a large
step damps the motion away), Newmark (trapezoidal) conserves it up to the nonlinear
solver's tolerance, symplectic Euler keeps it bounded. :func:`energy_report` measures
this from a run's statistics rows, so a user sees when a large step has damped the
motion away.

The scale is the energy exchanged in the motion: the largest drop of the potential
energy below its initial value, max_t (E_0 - Psi(t) - V(t)), or the largest kinetic
energy, whichever is larger (for a beam released from rest both are the swing energy).
The drift is (E_end - E_0) / scale, the excursion max_t |E(t) - E_0| / scale.
"""

from __future__ import annotations

import json
from pathlib import Path

from .body import body_pins

__all__ = ["energy_report", "initial_energies", "describe_energy", "write_summary",
           "DAMPED_THRESHOLD"]

#: A run that lost more than this fraction of the exchanged energy is flagged as damped.
DAMPED_THRESHOLD = 0.05


def initial_energies(sim) -> dict[str, float]:
    """Kinetic, elastic, gravitational and total energy of ``sim``'s initial state."""
    state = sim.initial_state()
    p = sim.problem
    p.u.x.array[:] = state.u
    p.v.x.array[:] = state.v
    return p.energies()


def energy_report(rows: list[dict], initial: dict[str, float], scene) -> dict:
    """Energy drift of a run (see the module docstring).

    Args:
        rows: The run's statistics rows (``kinetic``, ``elastic``, ``gravity``,
            ``total_energy`` per step).
        initial: Energies of the initial state (:func:`initial_energies`).
        scene: The scene; damping or moving pins make the energy not conserved.

    Returns:
        A dictionary with ``initial_energy``, ``final_energy``, ``exchanged_energy``,
        ``drift`` (signed, relative), ``max_excursion`` (relative), ``conservative``
        (whether the scene conserves energy) and ``damped`` (a conservative scene that
        lost more than :data:`DAMPED_THRESHOLD` of the exchanged energy).
    """
    e0 = initial["total_energy"]
    potential0 = initial["elastic"] + initial["gravity"]
    exchanged = max([abs(e0)] + [r["kinetic"] for r in rows]
                    + [potential0 - r["elastic"] - r["gravity"] for r in rows])
    moving = any(p["velocity"] is not None or p["angular_velocity"] != 0
                 for _, _, p in body_pins(scene))
    conservative = "damping" not in scene.data and not moving
    e_end = rows[-1]["total_energy"] if rows else e0
    if exchanged > 0.0:
        drift = (e_end - e0) / exchanged
        excursion = max(abs(r["total_energy"] - e0) for r in rows) / exchanged if rows else 0.0
    else:  # nothing moved: nothing to drift
        drift = excursion = 0.0
    return {"initial_energy": e0, "final_energy": e_end, "exchanged_energy": exchanged,
            "drift": drift, "max_excursion": excursion, "conservative": conservative,
            "damped": conservative and drift < -DAMPED_THRESHOLD}


def describe_energy(report: dict, integrator: str) -> str:
    """One line for the terminal: the drift, and a warning when the step damped the motion."""
    pct = 100.0 * report["drift"]
    base = (f"energy drift {pct:+.3g} % of the exchanged energy "
            f"({report['exchanged_energy']:.4g} J), max excursion "
            f"{100.0 * report['max_excursion']:.3g} %")
    if not report["conservative"]:
        return base + " (not conserved by design: damping or moving pins)"
    if report["damped"]:
        return (base + f"; numerical damping: {integrator} with this time step damped away "
                f"{-pct:.3g} % of the energy (use newmark or a smaller time.dt to keep "
                "the motion)")
    return base


def write_summary(path: Path, scene, rows: list[dict], report: dict) -> None:
    """``summary.json``: steps, final time, retries, iterations and the energy report."""
    summary = {
        "scene": scene.name, "integrator": scene["time"]["integrator"],
        "dt": scene["time"]["dt"], "steps": len(rows),
        "final_time": rows[-1]["time"] if rows else 0.0,
        "retries": sum(r.get("retries", 0) for r in rows),
        "newton_its": sum(r["newton_its"] for r in rows),
        "linear_its": sum(r["linear_its"] for r in rows),
        "energy": report,
    }
    Path(path).write_text(json.dumps(summary, indent=2) + "\n")
