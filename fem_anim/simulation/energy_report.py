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
The drift is (E_end - E_0) / scale, the excursion max_t |E(t) - E_0| / scale. When the
scale is below the round-off of the energies (E_Young |Omega| 1e-12, a strain of 1e-6: a
body at rest), no relative figure is given. Damping and friction only remove energy: a
gain is flagged for every scene without moving pins, a loss only for a conservative one.

Newmark and contact: the trapezoidal update applies the barrier force of a step's start over
half of the next step, after the contact has released, and gains energy at impacts; scenes
with contact are refused Newmark (:mod:`fem_anim.scene.contact_integrator`).

A scene with moving pins is not given a relative figure: the handles put energy in, and the
line gives the total energy before and after and what is stored at the end (kinetic,
elastic, gravity, barrier). A dissipative scene (damping, friction) gets its drift and the
largest rise above the initial energy, which it should never have.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from fem_anim.mesh.bodies import body_pins
from fem_anim.mesh.checks import cell_volumes
from fem_anim.problem.shell_terms import shell_thickness

__all__ = ["energy_report", "initial_energies", "describe_energy", "write_summary",
           "DAMPED_THRESHOLD", "ROUNDOFF_STRAIN", "moving_pins"]

#: A run that lost (gained) more than this fraction of the exchanged energy is flagged
#: as damped (as gaining energy).
DAMPED_THRESHOLD = 0.05
#: Energies below E_Young * volume * ROUNDOFF_STRAIN^2 are the solver's round-off, not
#: motion: no relative figure is computed from them (a body at rest has no "drift").
ROUNDOFF_STRAIN = 1.0e-6


def moving_pins(scene) -> bool:
    """Whether any pin of ``scene`` moves (a handle): it then works on the body."""
    return any(p["velocity"] is not None or p["angular_velocity"] != 0
               for _, _, p in body_pins(scene))


def _volume(domain) -> float:
    """|Omega| from the input mesh on rank 0 (simplex volumes; a shell's: its area)."""
    if domain.mesh.comm.rank != 0:
        return domain.mesh.comm.bcast(None, root=0)
    volume = float(np.sum(np.abs(cell_volumes(domain.points, domain.cells))))
    return domain.mesh.comm.bcast(volume, root=0)


def initial_energies(sim) -> dict[str, float]:
    """Kinetic, elastic, gravitational and total energy of ``sim``'s initial state, and
    ``roundoff``: the energy below which a figure is round-off (:data:`ROUNDOFF_STRAIN`)."""
    state = sim.initial_state()
    p = sim.problem
    p.u.x.array[:] = state.u
    p.v.x.array[:] = state.v
    energies = p.energies()
    young = sim.scene["material"]["youngs_modulus"]
    energies["roundoff"] = young * _volume(sim.domain) * shell_thickness(sim.scene) * \
        ROUNDOFF_STRAIN**2
    return energies


def energy_report(rows: list[dict], initial: dict[str, float], scene) -> dict:
    """Energy drift of a run (see the module docstring).

    Args:
        rows: The run's statistics rows (``kinetic``, ``elastic``, ``gravity``,
            ``total_energy`` per step).
        initial: Energies of the initial state (:func:`initial_energies`).
        scene: The scene; damping or moving pins make the energy not conserved.

    Returns:
        A dictionary with ``initial_energy``, ``final_energy``, ``exchanged_energy``,
        ``drift`` (signed, relative; None when the exchanged energy is at round-off
        level), ``max_excursion`` (relative, or None), ``conservative`` (whether the
        scene conserves energy: no damping, friction or moving pin), ``damped`` (a
        conservative scene that lost more than :data:`DAMPED_THRESHOLD` of the exchanged
        energy), ``gained`` (a scene without moving pins that gained as much: damping and
        friction only dissipate) and ``flagged`` (either).
        ``unconverged_steps`` lists the steps kept at the round-off floor of the objective
        without meeting their stopping test (``snes_reason`` =
        :data:`fem_anim.solver.stopping.POLISH_FAILED_REASON`); ``budget_steps`` those accepted
        at their iteration budget without meeting it (``solver.on_budget = "accept"``,
        :data:`fem_anim.solver.stopping.BUDGET_REASON`).
    """
    # here: importing PETSc waits for init_petsc
    from fem_anim.solver.stopping import BUDGET_REASON, POLISH_FAILED_REASON

    e0 = initial["total_energy"]
    potential0 = initial["elastic"] + initial["gravity"]
    exchanged = max([abs(e0)] + [r["kinetic"] for r in rows]
                    + [potential0 - r["elastic"] - r["gravity"] for r in rows])
    friction = any(ob["friction"] > 0 for ob in scene["obstacle"]) or \
        ("contact" in scene.data and scene["contact"]["friction"] > 0)
    moving = moving_pins(scene)
    conservative = not scene.damped and not friction and not moving and \
        "wind" not in scene.data  # a shell's drag dissipates
    e_end = rows[-1]["total_energy"] if rows else e0
    drift = excursion = None
    if exchanged > initial.get("roundoff", 0.0):
        drift = (e_end - e0) / exchanged
        excursion = max(abs(r["total_energy"] - e0) for r in rows) / exchanged if rows else 0.0
    rise = max([0.0] + [r["total_energy"] - e0 for r in rows]) / exchanged \
        if drift is not None else None
    damped = conservative and drift is not None and drift < -DAMPED_THRESHOLD
    # damping and friction only take energy away: a gain is flagged for them too (not for a
    # blowing [wind], which works on the body)
    blowing = "wind" in scene.data and any(scene["wind"]["velocity"])
    gained = not moving and drift is not None and drift > DAMPED_THRESHOLD and not blowing
    return {"initial_energy": e0, "final_energy": e_end, "exchanged_energy": exchanged,
            "drift": drift, "max_excursion": excursion, "max_rise": rise,
            "moving_pins": moving, "stored_energy": _stored(rows[-1] if rows else initial),
            "conservative": conservative,
            "damped": damped, "gained": gained, "flagged": damped or gained,
            "unconverged_steps": [int(r["step"]) for r in rows
                                  if r.get("snes_reason") == POLISH_FAILED_REASON],
            "budget_steps": [int(r["step"]) for r in rows
                             if r.get("snes_reason") == BUDGET_REASON]}


def _stored(row: dict) -> dict[str, float]:
    """The energy held at the end: kinetic, elastic, gravity and the barriers' (J)."""
    return {k: float(row.get(k) or 0.0) for k in ("kinetic", "elastic", "gravity", "contact")}


def _contact(scene) -> bool:
    """Whether the scene has contact: obstacles, or contact between bodies."""
    return bool(scene["obstacle"]) or "contact" in scene.data


def describe_energy(report: dict, scene) -> str:
    """One line for the terminal: the drift, and a warning for a gain or a loss that the
    scene does not explain, with advice only where it applies."""
    integrator = scene["time"]["integrator"]
    unconverged = report.get("unconverged_steps") or []
    unmet = (f"; {len(unconverged)} step(s) stopped at the round-off floor without meeting "
             f"the stopping test (first: step {unconverged[0]})") if unconverged else ""
    budget = report.get("budget_steps") or []
    if budget:
        unmet += (f"; {len(budget)} step(s) accepted at the iteration budget "
                  f"(solver.max_iterations) without meeting the stopping test "
                  f"(first: step {budget[0]})")
    if report["drift"] is None:
        return (f"no energy exchanged above round-off ({report['exchanged_energy']:.3g} J): "
                f"the body stayed at rest{unmet}")
    pct = 100.0 * report["drift"]
    if report.get("moving_pins"):  # handles put energy in: a % of the motion means nothing
        stored = report.get("stored_energy") or {}
        held = ", ".join(f"{k} {v:.4g}" for k, v in stored.items() if v)
        return (f"handles worked on the bodies: total energy {report['initial_energy']:.4g} J "
                f"-> {report['final_energy']:.4g} J, the handles' work less what damping and "
                f"friction took (not conserved by design); stored at the end: "
                f"{held or 'none'} J{unmet}")
    if not report["conservative"] and not report["gained"]:
        rise = report.get("max_rise") or 0.0
        return (f"energy drift {pct:+.3g} % of the exchanged energy "
                f"({report['exchanged_energy']:.4g} J): taken by damping, friction, drag and "
                f"{integrator}'s step (given by a wind), as designed; at most {100.0 * rise:.3g} % above its "
                f"start{unmet}")
    base = (f"energy drift {pct:+.3g} % of the exchanged energy "
            f"({report['exchanged_energy']:.4g} J), max excursion "
            f"{100.0 * report['max_excursion']:.3g} %{unmet}")
    if report["damped"]:
        # newmark is refused with contact (fem_anim.scene.contact_integrator)
        advice = "a smaller time.dt" if integrator == "newmark" or _contact(scene) else \
            "newmark or a smaller time.dt"
        return (base + f"; numerical damping: {integrator} with this time step damped away "
                f"{-pct:.3g} % of the energy (use {advice} to keep the motion)")
    if report["gained"]:
        why = "the time step or the solver tolerance: use a smaller time.dt"
        if _contact(scene) and integrator != "implicit_euler":
            why += " or time.integrator = \"implicit_euler\" (it cannot gain energy)"
        return base + f"; energy GAINED {pct:.3g} %, not conserved by the scheme: {why}"
    if not report["conservative"]:
        return base + " (not conserved by design: damping, friction or moving pins)"
    return base


def write_summary(path: Path, scene, rows: list[dict], report: dict,
                  provenance: dict | None = None) -> None:
    """``summary.json``: steps, final time, retries, iterations and the energy report, then
    ``provenance`` (software versions, PETSc options, wall time:
    :mod:`fem_anim.output.provenance`)."""
    summary = {
        "scene": scene.name, "integrator": scene["time"]["integrator"],
        "dt": scene["time"]["dt"], "steps": len(rows),
        "final_time": rows[-1]["time"] if rows else 0.0,
        "retries": sum(r.get("retries", 0) for r in rows),
        "newton_its": sum(r["newton_its"] for r in rows),
        "linear_its": sum(r["linear_its"] for r in rows),
        "energy": report,
    } | (provenance or {})
    Path(path).write_text(json.dumps(summary, indent=2) + "\n")
