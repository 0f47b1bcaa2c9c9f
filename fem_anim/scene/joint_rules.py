"""A shell beside solids in one scene (issue 30): the rules, and the two scenes it is run as.

A ``[[body]]`` with a ``shell`` table (``body[k].shell``, the keys of ``[shell]``) and a
surface mesh (``mesh.shape = "sheet"`` or a surface file) is a thin shell; the other bodies
are solids. The shell and the solids are two meshes (DOLFINx has one cell type per mesh)
stepped as ONE minimisation over both unknowns, with IPC's barrier between and within them
and the shell's thickness as its minimum distance (seed eq. 4;
:mod:`fem_anim.simulation.joint_loop`, docs/notes/shell_solid_coupling.md). The scene is run
as two scenes, each a scene of its own kind (:func:`split_joint_scene`): the solids' (the
solid bodies, without ``[contact]``) and the shell's (its body's tables at the top level, with
``[contact]``, which becomes the joint barrier). The keys shared by both are the scene's
(time, gravity, damping, obstacles, solver, contact, output). Refused, one line each: more than one
shell body, a shell body alone, a rotated shell, an offset surface file, ``[wind]``,
``contact.self = false``, and what either part's own rules refuse (P2 or Kirchhoff-Love
bending, the mixed formulation, Newmark and explicit integrators, filtered Hessians).
"""

from __future__ import annotations

from typing import Any

from fem_anim.errors import SceneError
from fem_anim.scene.shell_rules import SHELL_SHAPES, check_shell

__all__ = ["JOINT_INTEGRATORS", "check_joint", "check_joint_parts", "joint_parts",
           "shell_body"]

#: Integrators of a shell with solids: the implicit ones that contact takes (Newmark is
#: refused with contact in every scene: :mod:`fem_anim.scene.contact_integrator`).
JOINT_INTEGRATORS = ("implicit_euler", "bdf2")


def shell_body(data: dict[str, Any]) -> int | None:
    """The index of the ``[[body]]`` with a ``shell`` table (None: no shell body)."""
    shells = [k for k, body in enumerate(data.get("body") or []) if "shell" in body]
    return shells[0] if shells else None


def joint_parts(data: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The solids' and the shell's scene data of a validated scene with a shell body.

    The solids' scene holds the solid bodies, without ``[contact]``; the shell's holds its
    body's mesh (a sheet's origin moved by the body's offset), material, shell table, pins
    and initial velocity at the top level, with ``[contact]`` and ``solver.hessian =
    "exact"`` (the joint step's Hessian). Both keep the shared tables.
    """
    k = shell_body(data)
    body = data["body"][k]
    solid = {key: value for key, value in data.items() if key not in ("contact", "wind")}
    solid["body"] = [b for i, b in enumerate(data["body"]) if i != k]
    shell = {key: value for key, value in data.items() if key != "body"}
    mesh = dict(body["mesh"])
    if body["offset"] is not None and mesh["shape"] == "sheet":
        origin = mesh["origin"] or [0.0, 0.0, 0.0]
        mesh["origin"] = [float(a + b) for a, b in zip(origin, body["offset"])]
    shell.update({"name": body["name"], "mesh": mesh, "material": body["material"],
                  "shell": body["shell"], "pin": body["pin"], "region": [], "body": [],
                  "solver": data["solver"] | {"hessian": "exact"}})
    if "initial" in body:
        shell["initial"] = body["initial"]
    else:
        shell.pop("initial", None)
    return solid, shell


def check_joint_parts(solid: dict[str, Any], shell: dict[str, Any]) -> str | None:
    """The first reason the solids' and the shell's scene data cannot be stepped together,
    as one line (None: none). Each part's own rules are checked where it was validated."""
    if "shell" in solid or solid["mesh"]["dim"] != 3:
        return "the solids' scene must be a 3D solid scene (no [shell])"
    if "shell" not in shell:
        return "the shell's scene needs a [shell] table"
    if "contact" in solid:
        return "the solids' scene has no [contact]: the shell's [contact] is the joint one"
    if "contact" not in shell:
        return "the shell's scene needs [contact]: the barrier between the shell and the solids"
    if not shell["contact"]["self"]:
        return ("contact.self = false is refused with a shell body: the shell's layers meet "
                "themselves")
    if shell["shell"]["bending_model"] != "hinge":
        return "a shell with solids needs P1: shell.bending_model = \"hinge\""
    for part, who in ((solid, "solids"), (shell, "shell")):
        if part["element"]["degree"] != 1:
            return f"element.degree must be 1 with a shell and solids ({who}: " \
                   f"{part['element']['degree']})"
        if part["element"]["formulation"] != "displacement":
            return ("element.formulation must be \"displacement\" with a shell and solids, "
                    f"got {part['element']['formulation']!r}")
        if part["time"]["integrator"] not in JOINT_INTEGRATORS:
            return (f"time.integrator must be one of {', '.join(JOINT_INTEGRATORS)} with a "
                    f"shell and solids, got {part['time']['integrator']!r}")
        if part["solver"]["hessian"] not in ("exact", "auto"):
            return (f"solver.hessian must be \"exact\" with a shell and solids (the joint step "
                    f"assembles the exact Hessian), got {part['solver']['hessian']!r}")
    if solid["time"] != shell["time"]:
        return "the solids' and the shell's [time] tables must be equal"
    return None


def check_joint(data: dict[str, Any]) -> None:
    """The rules of a scene with a shell body (nothing without one).

    Args:
        data: The validated scene (every key present).

    Raises:
        SceneError: for the first rule broken, naming the keys and their values.
    """
    k = shell_body(data)
    if k is None:
        return
    bodies = data["body"]
    where = f"body[{k}]"
    if sum("shell" in b for b in bodies) > 1:
        raise SceneError("one [[body]] may have a shell table: several shells are one shell "
                         "body whose surface has several pieces (mesh.shape = \"file\")")
    if len(bodies) == 1:
        raise SceneError(f"{where}.shell without a solid [[body]] beside it: a shell alone is "
                         "a scene with [mesh] and [shell]")
    body = bodies[k]
    if body["mesh"]["shape"] not in SHELL_SHAPES:
        raise SceneError(f"{where}.mesh.shape must be \"sheet\" or \"file\" (a triangle "
                         f"surface) for a shell body, got {body['mesh']['shape']!r}")
    for i, other in enumerate(bodies):
        if i != k and other["mesh"]["shape"] == "sheet":
            raise SceneError(f"body[{i}].mesh.shape = \"sheet\" is a surface: give that body "
                             "a shell table (one shell body per scene)")
    if body["rotation"] is not None:
        raise SceneError(f"{where}.rotation is not supported for a shell body: place a sheet "
                         "with mesh.origin")
    if body["offset"] is not None and body["mesh"]["shape"] == "file":
        raise SceneError(f"{where}.offset is not supported for a shell surface file: place "
                         "the surface in the file")
    if "wind" in data:
        raise SceneError("[wind] is not supported with a shell body beside solids")
    solid, shell = joint_parts(data)
    error = check_joint_parts(solid, shell)
    if error:
        raise SceneError(error)
    check_shell(shell)
