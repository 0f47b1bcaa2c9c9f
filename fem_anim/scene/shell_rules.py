"""The rules of a shell scene (``[shell]``): what a thin shell body may be combined with.

A shell is one body whose mesh is a triangle surface in 3D (``mesh.shape = "sheet"`` or a
surface file), P1, with a membrane model of :mod:`fem_anim.forms.shell_membrane` and the
hinge bending of :mod:`fem_anim.forms.shell_bending`, or P2 with the Kirchhoff-Love bending of
:mod:`fem_anim.forms.shell_kirchhoff_love` (``shell.bending_model``; no contact or obstacles
yet). A shell beside solids is a ``[[body]]`` with a ``shell`` table
(:mod:`fem_anim.scene.joint_rules`, whose shell part is checked here too). What its energy
does not have yet is refused here, one rule a line: regions, ``[contact]`` without self
contact (a shell scene has one body, so its only IPC pairs are the shell's own), obstacles
with a consistent mass (the barrier's vertex rule must be the mass's), P2, the mixed
formulation, stiffness-proportional damping, the Hessian filters of solids' ``psi(F)`` and
the ``det F`` inversion filter (a surface's 3x3 ``det(I + grad u)`` is zero; its area ratio
is positive by construction).
"""

from __future__ import annotations

from typing import Any

from fem_anim.errors import SceneError

__all__ = ["MAX_SHELL_CELLS", "SHELL_MODELS", "SHELL_SHAPES", "check_shell",
           "shell_bending_value"]

#: Membrane models a shell takes (``fem_anim.forms.shell_membrane.MEMBRANE_MODELS``).
SHELL_MODELS = ("stvk", "neohookean")
#: ``mesh.shape`` values that give a surface.
SHELL_SHAPES = ("sheet", "file")
#: At most this many triangles in a sheet (a larger one is a typo, not a scene).
MAX_SHELL_CELLS = 2.0e7


def shell_bending_value(v) -> str | None:
    """``shell.bending``: ``"derived"`` or a number >= 0 (the constraint's phrase, or None)."""
    if isinstance(v, str):
        return None if v == "derived" else "must be a number >= 0 or \"derived\""
    return None if v >= 0 else "must be >= 0 (or \"derived\")"


def _refuse(data: dict[str, Any]) -> str | None:
    """The first rule a ``[shell]`` scene breaks, as a message (None: none)."""
    mesh, element, material = data["mesh"], data["element"], data["material"]
    if mesh["dim"] != 3:
        return f"[shell] needs mesh.dim = 3 (a surface in 3D), got {mesh['dim']}"
    if mesh["shape"] not in SHELL_SHAPES:
        return (f"[shell] needs mesh.shape = \"sheet\" or \"file\" (a triangle surface), got "
                f"{mesh['shape']!r}")
    if mesh["shape"] == "sheet" and len(mesh["size"]) != 2:
        return f"mesh.size of a sheet must have 2 entries (x, y), got {mesh['size']}"
    kl = data["shell"]["bending_model"] == "kirchhoff_love"
    if element["degree"] != (2 if kl else 1):
        if kl:
            return (f"shell.bending_model = \"kirchhoff_love\" needs element.degree = 2 (a "
                    f"P2 displacement), got {element['degree']}")
        return (f"[shell] supports element.degree = 1 only (P1 membrane and hinge bending; "
                f"P2 with shell.bending_model = \"kirchhoff_love\"), got {element['degree']}")
    if kl and "contact" in data:
        return "[shell] with [contact] needs P1: shell.bending_model = \"hinge\""
    if kl and data["obstacle"]:
        return "[shell] with [[obstacle]] needs P1: shell.bending_model = \"hinge\""

    if element["formulation"] != "displacement":
        return "[shell] supports element.formulation = \"displacement\" only"
    if material["model"] not in SHELL_MODELS:
        return (f"material.model = {material['model']!r} has no membrane form: a [shell] takes "
                f"{' or '.join(SHELL_MODELS)}")
    if "contact" in data and not data["contact"]["self"]:
        return ("[shell] with contact.self = false has no contact pairs (a shell scene has one "
                "body): set contact.self = true or remove [contact]")
    if data["obstacle"] and material["mass"] != "lumped":
        return ("[shell] with [[obstacle]] needs material.mass = \"lumped\" (the barrier acts "
                "at the vertices, by the lumped mass's vertex rule; FFCx 0.5 miscompiles two "
                "rules in one kernel), got " + repr(material["mass"]))
    if data["region"]:
        return "[shell] with [[region]] is not supported: a shell has one material"
    if "damping" in data and data["damping"]["beta"] != 0:
        return ("damping.beta (stiffness-proportional) is not supported with [shell], got "
                f"{data['damping']['beta']}; use damping.alpha")
    if data["solver"]["hessian"] != "exact":
        return (f"solver.hessian = {data['solver']['hessian']!r} filters a solid's psi(F); a "
                "[shell] takes \"exact\"")
    if data["solver"]["inversion_filter"]:
        return ("solver.inversion_filter = true watches det F of solids; a shell's area ratio "
                "is positive by construction: leave it unset")
    if mesh["shape"] == "sheet":
        cells = 2 * (mesh["size"][0] / mesh["element_size"] + 1) * \
            (mesh["size"][1] / mesh["element_size"] + 1)
        if cells > MAX_SHELL_CELLS:
            return (f"mesh.element_size = {mesh['element_size']} would make about {cells:.2g} "
                    f"triangles for this sheet (at most {MAX_SHELL_CELLS:.0e})")
    return None


def check_shell(data: dict[str, Any]) -> None:
    """The rules of a ``[shell]`` scene, and a sheet without one.

    Args:
        data: The validated scene (every key present).

    Raises:
        SceneError: for the first rule broken, naming the keys and their values.
    """
    if "shell" not in data:
        if "wind" in data:
            raise SceneError("[wind] acts on a shell's surface: add a [shell] table (a "
                             "solid body has no wind drag)")
        if data["mesh"]["shape"] == "sheet":
            raise SceneError("mesh.shape = \"sheet\" is a surface: add a [shell] table with its "
                             "thickness to make the body a shell")
        return
    message = _refuse(data)
    if message is not None:
        raise SceneError(message)
