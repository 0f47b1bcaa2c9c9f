"""The time integrator of a scene with contact: one that cannot pump energy in.

A scene has contact when it declares ``[[obstacle]]`` tables or ``[contact]`` (on by default
with several bodies). Its step objective holds a barrier whose force is large at the
deepest point of an impact and zero one step later. Implicit Euler's step is the minimiser
of g(x) = 1/2 ||x - x_n - h v_n||_M^2 + h^2 E(x) (seed eq. 4 with w = h^2); comparing
g(x_{n+1}) with g at the start x_n gives

    T_{n+1} + E(x_{n+1}) + 1/2 ||v_{n+1} - v_n||_M^2 <= T_n + E(x_n),

so the total energy (kinetic, elastic, gravity, barrier) cannot rise whatever the barrier
does within the step; lagged friction only adds a non-negative term zero at x_n. BDF2 is
not covered by this inequality but dissipates at impacts in every scene measured
(``docs/contact.md``). Newmark's trapezoidal velocity update applies the barrier force of a
step's start over half of the next step, after the contact has released: an impulse no
energy paid for, which a smaller step does not cure; symplectic Euler linearises the
barrier at x_n and steps over it. Both are refused with contact.

:func:`choose_integrator` gives a contact scene that names no ``time.integrator``
:data:`CONTACT_INTEGRATOR` instead of the global default; :func:`check_integrator` refuses
the others with one line saying what to change; :func:`integrator_note` is the line a run
prints first.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fem_anim.errors import SceneError

__all__ = ["CONTACT_INTEGRATOR", "CONTACT_INTEGRATORS", "check_integrator", "choose_integrator",
           "has_contact", "integrator_note"]

#: The integrator of a contact scene that names none (it cannot gain energy: module
#: docstring).
CONTACT_INTEGRATOR = "implicit_euler"
#: The integrators a scene with contact may choose.
CONTACT_INTEGRATORS = ("implicit_euler", "bdf2")


def has_contact(data: Mapping[str, Any]) -> bool:
    """Whether validated scene tables declare contact (obstacles or ``[contact]``)."""
    return bool(data.get("obstacle")) or "contact" in data


def choose_integrator(raw: Mapping[str, Any], data: dict[str, Any]) -> None:
    """Set ``time.integrator`` to :data:`CONTACT_INTEGRATOR` in ``data`` when the scene
    has contact and ``raw`` (the tables as given, overrides applied) names none.

    Args:
        raw: The scene's tables as parsed.
        data: The validated tables (modified in place).
    """
    time = raw.get("time")
    named = isinstance(time, Mapping) and time.get("integrator") is not None
    if has_contact(data) and not named:
        data["time"]["integrator"] = CONTACT_INTEGRATOR


def check_integrator(data: Mapping[str, Any]) -> None:
    """Refuse an integrator that can gain energy at impacts in a scene with contact.

    Raises:
        SceneError: naming ``time.integrator``, the value and what to set instead.
    """
    name = data["time"]["integrator"]
    if has_contact(data) and name not in CONTACT_INTEGRATORS:
        why = {"newmark": "its trapezoidal velocity update gives an impulse at every impact "
               "that no energy pays for",
               "symplectic_euler": "it linearises the barrier at the step's start and steps "
               "over it"}.get(name, "it is not energy-safe with a barrier")
        raise SceneError(f"time.integrator = \"{name}\" is refused with contact "
                         f"([[obstacle]] or [contact]): {why}; set time.integrator = "
                         f"\"{CONTACT_INTEGRATOR}\" (or \"bdf2\"), or leave it out")


def integrator_note(data: Mapping[str, Any]) -> str | None:
    """The run's first line for a contact scene: which integrator steps it and why.

    Returns:
        The line (without the ``fem-anim:`` prefix), or None for a scene without contact.
    """
    if not has_contact(data):
        return None
    name = data["time"]["integrator"]
    why = ("it cannot gain energy at impacts" if name == "implicit_euler"
           else "second order; it lost energy at impacts in every scene measured")
    note = (f"contact scene: time.integrator = \"{name}\" ({why}; newmark is refused with "
            f"contact, default {CONTACT_INTEGRATOR})")
    if data["solver"].get("mode") == "preview":  # fem_anim.scene.modes
        note += ("; solver.mode = \"preview\" solves each step to the stopping test here (one "
                 "Newton step per step gains energy at impacts)")
    return note
