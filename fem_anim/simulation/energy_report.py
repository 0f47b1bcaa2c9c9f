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

The balance. The stored energy E = T + Psi + V_gravity + barrier (``total_energy`` of
``stats.csv``) changes by what the handles put in, W = sum of the steps' ``handle_work``
(:mod:`fem_anim.simulation.handle_work`), less what damping, friction and the time step
took: D = E_0 + W - E_end (``dissipated``), which must not be negative. A scene with
moving pins is given no relative drift (the handles put energy in): its line gives the
stored energy before and after, W and D; it is flagged when D < 0 by more than
:data:`DAMPED_THRESHOLD` of the energy moved (the exchanged energy or the handles' work,
whichever is larger). A dissipative scene (damping, friction) gets the stored energy
before and after, D, and the largest rise above the initial energy, which it should never
have. A scene with contact whose bodies end at rest (kinetic energy below 1 % of the
exchanged energy) lost its motion at the impacts, as the implicit integrators that contact
allows do: that is said, not flagged. Every figure is recomputable from ``stats.csv``
(``total_energy``, ``kinetic``, ``handle_work``) and ``summary.json``'s ``initial_energy``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from fem_anim.mesh.bodies import body_pins
from fem_anim.mesh.checks import cell_volumes
from fem_anim.problem.shell_terms import shell_thickness

__all__ = ["energy_report", "initial_energies", "describe_energy", "write_summary",
           "DAMPED_THRESHOLD", "ROUNDOFF_STRAIN", "AT_REST", "moving_pins", "roundoff_energy"]

#: A run that lost (gained) more than this fraction of the exchanged energy is flagged
#: as damped (as gaining energy).
DAMPED_THRESHOLD = 0.05
#: A run whose last kinetic energy is below this fraction of the exchanged energy ended at
#: rest.
AT_REST = 0.01
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
    energies["roundoff"] = roundoff_energy(sim.scene, sim.domain)
    return energies


def roundoff_energy(scene, domain) -> float:
    """E_Young |Omega| t ROUNDOFF_STRAIN^2 (J; t = 1 for a solid): the energy below which a
    figure of this scene's body is round-off (collective)."""
    young = scene["material"]["youngs_modulus"]
    return young * _volume(domain) * shell_thickness(scene) * ROUNDOFF_STRAIN**2


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
        energy and did not come to rest at contact), ``gained`` (a scene without moving
        pins that gained as much: damping and friction only dissipate; with moving pins,
        a negative ``dissipated`` beyond that fraction of the energy moved) and
        ``flagged`` (either). The balance: ``initial_stored_energy`` and
        ``stored_energy`` (kinetic, elastic, gravity, barrier at the start and the end),
        ``handle_work`` (W, the sum of the rows' ``handle_work``; 0 without moving pins,
        None for rows without it), ``dissipated`` (D = E_0 + W - E_end, taken by
        damping, friction and the time step; None when W is), ``dissipated_by`` (which
        of them the scene has), ``came_to_rest`` (a scene
        with contact whose last kinetic energy is below :data:`AT_REST` of the exchanged
        energy).
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
    moving = moving_pins(scene)
    exchanged = max([abs(e0)] + [r["kinetic"] for r in rows]
                    + [potential0 - r["elastic"] - r["gravity"] for r in rows])
    friction = any(ob["friction"] > 0 for ob in scene["obstacle"]) or \
        ("contact" in scene.data and scene["contact"]["friction"] > 0)
    conservative = not scene.damped and not friction and not moving and \
        "wind" not in scene.data  # a shell's drag dissipates
    e_end = rows[-1]["total_energy"] if rows else e0
    # the handles' work; None for rows without it (a run begun before it was recorded)
    works = [r.get("handle_work") for r in rows]
    work = float(sum(works)) if all(isinstance(w, (int, float)) for w in works) else None
    if not moving:
        work = 0.0  # pins that do not move do no work
    dissipated = None if work is None else e0 + work - e_end
    moved = max(exchanged, sum(abs(w) for w in works)) if moving and work is not None \
        else exchanged
    at_rest = bool(rows) and rows[-1]["kinetic"] <= AT_REST * exchanged
    drift = excursion = None
    if exchanged > initial.get("roundoff", 0.0):
        drift = (e_end - e0) / exchanged
        excursion = max(abs(r["total_energy"] - e0) for r in rows) / exchanged if rows else 0.0
    rise = max([0.0] + [r["total_energy"] - e0 for r in rows]) / exchanged \
        if drift is not None else None
    blowing = "wind" in scene.data and any(scene["wind"]["velocity"])
    came_to_rest = _contact(scene) and at_rest  # impacts took the motion, by design
    damped = conservative and drift is not None and drift < -DAMPED_THRESHOLD and \
        not came_to_rest
    # damping and friction only take energy away: a gain is flagged for them too (not for a
    # blowing [wind], which works on the body), and with handles when the stored energy rose
    # by more than their work
    gained = not moving and drift is not None and drift > DAMPED_THRESHOLD and not blowing
    if moving and dissipated is not None and moved > initial.get("roundoff", 0.0) and \
            not blowing:
        gained = dissipated < -DAMPED_THRESHOLD * moved
    return {"initial_energy": e0, "final_energy": e_end, "exchanged_energy": exchanged,
            "drift": drift, "max_excursion": excursion, "max_rise": rise,
            "moving_pins": moving, "stored_energy": _stored(rows[-1] if rows else initial),
            "initial_stored_energy": _stored(initial), "handle_work": work,
            "dissipated": dissipated, "came_to_rest": came_to_rest,
            "dissipated_by": ["damping"] * scene.damped + ["friction"] * friction +
            ["the wind's drag"] * ("wind" in scene.data) +
            [f"{scene['time']['integrator']}'s step"],
            "conservative": conservative,
            "damped": damped, "gained": gained, "flagged": damped or gained,
            "unconverged_steps": [int(r["step"]) for r in rows
                                  if r.get("snes_reason") == POLISH_FAILED_REASON],
            "budget_steps": [int(r["step"]) for r in rows
                             if r.get("snes_reason") == BUDGET_REASON]}


def _stored(row: dict) -> dict[str, float]:
    """The energy held at the end: kinetic, elastic, gravity and the barriers' (J)."""
    return {k: float(row.get(k) or 0.0) for k in ("kinetic", "elastic", "gravity", "contact")}


def _held(report: dict) -> str:
    """``E_0 J -> E_end J (what is held at the end)``."""
    stored = report.get("stored_energy") or {}
    held = ", ".join(f"{'barrier' if k == 'contact' else k} {v:.4g}"
                     for k, v in stored.items() if v)
    return (f"{report['initial_energy']:.4g} J -> {report['final_energy']:.4g} J "
            f"({held or 'none'} J)")


def _took(report: dict, integrator: str) -> str:
    """What the handles put in and what damping, friction and the step took (J)."""
    work, dissipated = report.get("handle_work"), report.get("dissipated")
    if dissipated is None:  # rows without the handles' work
        return f"{report['initial_energy'] - report['final_energy']:.4g} J less in store"
    line = f"handles did {work:+.4g} J of work; " if report.get("moving_pins") else ""
    by = report.get("dissipated_by") or [f"{integrator}'s step"]
    by = " and ".join([", ".join(by[:-1]), by[-1]] if len(by) > 1 else by)
    return line + f"{by} took {dissipated:.4g} J"


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
        line = (f"handles worked on the bodies: stored energy {_held(report)}; "
                f"{_took(report, integrator)}")
        if report["gained"]:
            return (line + "; energy GAINED beyond the handles' work, not conserved by the "
                    f"scheme: use a smaller time.dt{unmet}")
        return line + f" (not conserved by design){unmet}"
    if report.get("came_to_rest") and not report["gained"]:
        return (f"the bodies came to rest: stored energy {_held(report)}; "
                f"{_took(report, integrator)}, as designed (an implicit step damps the motion "
                f"at impacts){unmet}")
    if not report["conservative"] and not report["gained"]:
        rise = report.get("max_rise") or 0.0
        return (f"stored energy {_held(report)}; {_took(report, integrator)}, as designed; "
                f"at most {100.0 * rise:.3g} % of the exchanged energy "
                f"({report['exchanged_energy']:.4g} J) above its start{unmet}")
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
        "retry_wall_s": sum(r.get("retry_wall_s", 0.0) for r in rows),
        "newton_its": sum(r["newton_its"] for r in rows),
        "linear_its": sum(r["linear_its"] for r in rows),
        "energy": report,
    } | (provenance or {})
    Path(path).write_text(json.dumps(summary, indent=2) + "\n")
