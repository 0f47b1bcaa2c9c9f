"""Contact settings bounded by the scene's own scales, and handles that contradict contact.

The barrier of seed eq. 4's contact energy (``[contact]``, ``[[obstacle]]``) works in double
precision between two scales of the scene: its size L (the bounding box of the bodies at rest)
and its element size h. Each check below refuses, before anything is built, a value that
cannot give a step that ends:

* ``dhat`` at least :data:`MIN_DHAT_RATIO` L: a distance is a difference of coordinates of size
  up to L, resolved to eps L (eps the double precision's 2.2e-16); d-hat must span 1e5 of those
  units, so gaps of a thousandth of d-hat are still resolved to a hundred; below that the
  barrier acts on round-off and the CCD bisects without end; and smaller than the smallest element
  size h (larger, a body's own neighbouring surface elements are all pairs at rest).
* ``stiffness`` kappa (Pa) such that the barrier's stiffness against an element's,
  r = (kappa / E) (h / dhat), lies in [:data:`MIN_BARRIER_RATIO`, :data:`MAX_BARRIER_RATIO`]:
  a larger r leaves the Newton system fewer than four digits, a smaller one balances contact
  forces only at distances below round-off.
* ``friction`` mu at most :data:`MAX_FRICTION` (Coulomb coefficients of real materials are
  below about 2; the lagged friction Hessian scales with mu).
* Handles (``[[pin]]`` with a ``velocity``) that drive held vertices of two pins (two bodies,
  or two parts of one body) into each other, or into an obstacle plane, within the run's time:
  held vertices cannot yield, so the barrier between them grows without bound. A pin's held
  vertices are bounded by its box intersected with its body's bounding box at rest; pins that
  turn (``angular_velocity``) are not predicted.

Every rule raises :class:`~fem_anim.errors.SceneError` naming the key, the bound and the value.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from fem_anim.errors import SceneError

__all__ = ["MIN_DHAT_RATIO", "MIN_BARRIER_RATIO", "MAX_BARRIER_RATIO", "MAX_FRICTION",
           "check_contact_limits", "body_box"]

MIN_DHAT_RATIO = 1.0e5 * float(np.finfo(float).eps)
MIN_BARRIER_RATIO = 1.0e-8
MAX_BARRIER_RATIO = 1.0e12
MAX_FRICTION = 10.0


def body_box(mesh: dict[str, Any], offset, rotation) -> np.ndarray | None:
    """The axis-aligned bounding box (2, d) of a gmsh body at rest in scene coordinates.

    Args:
        mesh: The body's validated ``[mesh]`` table.
        offset: The body's ``offset`` (None: none).
        rotation: The body's ``rotation`` in degrees (None: none), R = R_z R_y R_x.

    Returns:
        Rows (lower corner, upper corner); None for ``shape = "file"`` (known only when read).
    """
    d, shape = mesh["dim"], mesh["shape"]
    o = np.zeros(d) if mesh["origin"] is None else np.asarray(mesh["origin"], float)
    r, length, a = mesh["radius"], mesh["length"], mesh["minor_radius"]
    if shape == "box":
        lo, hi = o, o + np.asarray(mesh["size"], float)
    elif shape == "sphere":
        lo, hi = o - r, o + r
    elif shape in ("cylinder", "capsule"):
        cap = r if shape == "capsule" else 0.0
        lo, hi = o - r, o + r
        lo[0], hi[0] = o[0] - cap, o[0] + length + cap
    elif shape == "torus":
        lo, hi = o - (r + a), o + (r + a)
    else:
        return None
    corners = np.array(list(itertools.product(*zip(lo, hi))))
    placed = corners @ _rotation(rotation, d).T
    placed = placed + (0.0 if offset is None else np.asarray(offset, float))
    return np.array([placed.min(axis=0), placed.max(axis=0)])


def _rotation(angles, d: int) -> np.ndarray:
    """R = R_z R_y R_x for angles in degrees about x, y, z (2D: one angle about z), the
    placement of :func:`fem_anim.mesh.bodies.rotation_matrix` (which needs no mesh either,
    but lives below DOLFINx's import)."""
    a = np.radians(np.asarray(angles if angles is not None else [0.0] * (3 if d == 3 else 1),
                              dtype=float))
    c, s = np.cos(a), np.sin(a)
    if d == 2:
        return np.array([[c[0], -s[0]], [s[0], c[0]]])
    Rx = np.array([[1, 0, 0], [0, c[0], -s[0]], [0, s[0], c[0]]])
    Ry = np.array([[c[1], 0, s[1]], [0, 1, 0], [-s[1], 0, c[1]]])
    Rz = np.array([[c[2], -s[2], 0], [s[2], c[2], 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _element_size(mesh: dict[str, Any]) -> float | None:
    if mesh["shape"] == "file":
        return None
    if mesh["shape"] == "box" and mesh["divisions"] is not None:
        return min(s / n for s, n in zip(mesh["size"], mesh["divisions"]))
    return float(mesh["element_size"])


def _bodies(data: dict[str, Any]) -> list[dict[str, Any]]:
    """Each body's name, mesh, bounding box, pins and Young's moduli (the top-level body if
    there is no ``[[body]]``)."""
    if data["body"]:
        items = [(b["name"], b, b["pin"], f"body[{k}].") for k, b in enumerate(data["body"])]
    else:
        items = [("body", {"mesh": data["mesh"], "material": data["material"],
                           "offset": None, "rotation": None}, data["pin"], "")]
    return [{"label": name, "mesh": b["mesh"], "pins": pins, "prefix": prefix,
             "E": [b["material"]["youngs_modulus"]] + [r["youngs_modulus"] for r in
                                                       b.get("region", []) if
                                                       r["youngs_modulus"] is not None],
             "box": body_box(b["mesh"], b["offset"], b["rotation"])}
            for name, b, pins, prefix in items]


def _check_barrier(where: str, cfg: dict[str, Any], bodies: list[dict], size: float) -> None:
    """dhat, stiffness and friction of ``[contact]`` or one ``[[obstacle]]``."""
    dhat = cfg["dhat"]
    if size > 0 and dhat < MIN_DHAT_RATIO * size:
        raise SceneError(f"{where}.dhat must be at least {MIN_DHAT_RATIO:.2g} times the scene's "
                         f"size ({size:.3g} m), {MIN_DHAT_RATIO * size:.3g} m: smaller "
                         f"distances are lost in the round-off of the coordinates, got {dhat}")
    for body in bodies if where == "contact" else ():
        extent = None if body["box"] is None else float(np.min(body["box"][1] - body["box"][0]))
        if extent is not None and not dhat < extent:  # as the set-up's check, said earlier
            raise SceneError(f"contact.dhat must be smaller than every body; body "
                             f"{body['label']!r} is only {extent:.3g} m across, got {dhat}")
    sizes = [h for h in (_element_size(b["mesh"]) for b in bodies) if h is not None]
    if sizes and not dhat < min(sizes):
        raise SceneError(f"{where}.dhat must be smaller than the smallest element size "
                         f"({min(sizes):.3g} m), got {dhat}")
    kappa = cfg["stiffness"]
    if isinstance(kappa, (int, float)) and sizes:
        E = [e for b in bodies for e in b["E"]]
        low = kappa / max(E) * min(sizes) / dhat
        high = kappa / min(E) * max(sizes) / dhat
        if high > MAX_BARRIER_RATIO or low < MIN_BARRIER_RATIO:
            bound = MAX_BARRIER_RATIO * min(E) * dhat / max(sizes) if high > MAX_BARRIER_RATIO \
                else MIN_BARRIER_RATIO * max(E) * dhat / min(sizes)
            side = "at most" if high > MAX_BARRIER_RATIO else "at least"
            hint = " (or use \"adaptive\")" if where == "contact" else ""
            raise SceneError(f"{where}.stiffness must be {side} {bound:.3g} Pa for this scene "
                             "(the barrier's stiffness against an element's, (kappa / E) "
                             f"(h / dhat), within [{MIN_BARRIER_RATIO:g}, "
                             f"{MAX_BARRIER_RATIO:g}]), got {kappa}{hint}")
    if cfg["friction"] > MAX_FRICTION:
        raise SceneError(f"{where}.friction must be at most {MAX_FRICTION:g} (a Coulomb "
                         f"coefficient; real materials are below about 2), got {cfg['friction']}")


def _held_boxes(data: dict[str, Any], bodies: list[dict]) -> list[tuple]:
    """(path, box, velocity, until) of each pin's held vertices (box ∩ its body's box)."""
    held = []
    for body in bodies:
        for i, pin in enumerate(body["pins"]):
            if pin["angular_velocity"] != 0:
                continue
            box = np.array([pin["min"], pin["max"]], float)
            if body["box"] is not None:
                box = np.array([np.maximum(box[0], body["box"][0]),
                                np.minimum(box[1], body["box"][1])])
            if np.any(box[0] > box[1]):
                continue  # holds nothing of its body (another rule's business)
            v = np.zeros(box.shape[1]) if pin["velocity"] is None else \
                np.asarray(pin["velocity"], float)
            held.append((f"{body['prefix']}pin[{i}] ({pin['name']})", box, v, pin["until"]))
    return held


def _first_meeting(a: tuple, b: tuple, gap: float, end: float) -> float | None:
    """The first time in [0, end] at which two translating held boxes come within ``gap``.

    On each piece of time between the handles' stops the boxes move linearly, so each face
    condition (box B's lower face at most ``gap`` past box A's upper face, and the reverse,
    on every axis) holds on an interval of t; the boxes are within ``gap`` on the
    intersection of these intervals (exact, no sampling).

    Returns:
        The time, or None: never, or already within ``gap`` at rest (a shared or touching
        pin, not a drive).
    """
    (_, A, va, ua), (_, B, vb, ub) = a, b

    def shift(v, until, t):
        return v * (t if until is None else min(t, until))

    def conditions(t):  # c_k(t) <= gap for every k: the boxes are within gap
        P, Q = A + shift(va, ua, t), B + shift(vb, ub, t)
        return np.concatenate([Q[0] - P[1], P[0] - Q[1]])

    if np.all(conditions(0.0) <= gap):
        return None
    stops = sorted({0.0, end, *(t for t in (ua, ub) if t is not None and t < end)})
    for t0, t1 in zip(stops[:-1], stops[1:]):
        c0, c1 = conditions(t0), conditions(t1)
        lo, hi = t0, t1
        for k0, k1 in zip(c0, c1):  # linear on the piece: c(t) = k0 + (k1 - k0) s
            if k1 == k0:
                if k0 > gap:
                    lo, hi = 1.0, 0.0
                continue
            cross = t0 + (gap - k0) / (k1 - k0) * (t1 - t0)
            if k1 > k0:
                hi = min(hi, cross)
            else:
                lo = max(lo, cross)
        if lo <= hi:
            return float(lo)
    return None


def _check_handles(data: dict[str, Any], bodies: list[dict], dhat: float) -> None:
    """Handles driving held vertices into each other or into an obstacle plane."""
    held = _held_boxes(data, bodies)
    if not any(np.any(v != 0) for _, _, v, _ in held):
        return
    end = data["time"]["dt"] * data["time"]["steps"]
    for a, b in itertools.combinations(held if math.isfinite(dhat) else [], 2):
        if np.all(a[2] == b[2]) and a[3] == b[3]:
            continue  # moving together
        t = _first_meeting(a, b, dhat, end)
        if t is not None:
            raise SceneError(f"{a[0]} and {b[0]} drive held vertices into each other (their "
                             f"boxes of held vertices meet at t = {t:.3g} s, before the end "
                             f"t = {end:.3g} s); held vertices cannot yield to contact: change "
                             "a velocity or until")
    for i, obstacle in enumerate(data["obstacle"]):
        if obstacle["type"] != "plane":
            continue
        n = np.asarray(obstacle["normal"], float)
        n = n / np.linalg.norm(n)
        p = np.zeros_like(n) if obstacle["point"] is None else np.asarray(obstacle["point"], float)
        for where, box, v, until in held:
            if not np.any(v):
                continue
            corners = np.array(list(itertools.product(*zip(*box))))
            lowest = float(np.min((corners - p) @ n))  # the held part's distance at rest
            moved = float(v @ n) * (data["time"]["dt"] * data["time"]["steps"] if until is None
                                    else min(until, end))
            if lowest > obstacle["dhat"] and lowest + moved <= obstacle["dhat"]:
                raise SceneError(f"{where} drives held vertices into obstacle[{i}] "
                                 f"({obstacle['name']}) before the end t = {end:.3g} s; held "
                                 "vertices cannot yield to contact: change its velocity or "
                                 "until")


def check_contact_limits(data: dict[str, Any]) -> None:
    """The rules of the module docstring, on a scene whose keys each passed their checks.

    Args:
        data: The validated scene (every key present).

    Raises:
        SceneError: for the first rule broken.
    """
    if "contact" not in data and not data["obstacle"]:
        return
    bodies = _bodies(data)
    boxes = [b["box"] for b in bodies if b["box"] is not None]
    size = float(np.linalg.norm(np.max([b[1] for b in boxes], axis=0)
                                - np.min([b[0] for b in boxes], axis=0))) if boxes else 0.0
    if "contact" in data:
        _check_barrier("contact", data["contact"], bodies, size)
    for i, obstacle in enumerate(data["obstacle"]):
        cfg = dict(obstacle)
        if cfg["stiffness"] is None:
            cfg["stiffness"] = data["material"]["youngs_modulus"]
        _check_barrier(f"obstacle[{i}]", cfg, bodies, size)
    dhat = data["contact"]["dhat"] if "contact" in data else 0.0
    if "contact" in data or data["obstacle"]:
        _check_handles(data, bodies, dhat if "contact" in data else -math.inf)
