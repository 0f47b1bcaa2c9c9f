"""The parameters' names: which scene keys can be differentiated (seed eq. 4's constants).

A parameter is a scalar named by its scene key:

* ``material.youngs_modulus`` (E, Pa), ``material.poisson_ratio`` (nu),
  ``material.density`` (rho, kg/m^3): the scene's ``[material]`` (with ``[[region]]``
  entries: on the cells no region claims);
* ``region.NAME.material.KEY``: the same constants of the ``[[region]]`` named NAME;
* ``body.NAME.material.KEY``: those of the ``[[body]]`` named NAME (and
  ``body.NAME.region.R.material.KEY`` of its ``[[body.region]]`` R);
* ``damping.alpha`` (1/s) and ``damping.beta`` (s): the Rayleigh coefficients of
  ``[damping]``, C = alpha M + beta K_0 (seed eq. 4's dissipation term);
* the components of ``initial.velocity`` (``initial.velocity[0]``, ... in m/s: the rigid
  initial velocity; the key ``initial.velocity`` names all d components), and of a body's
  ``body.NAME.initial.velocity``;
* the initial spin ``initial.angular_velocity`` (rad/s; 3 components ``[0]``, ``[1]``,
  ``[2]`` in 3D, one number about z in 2D) and a body's ``body.NAME.initial.angular_velocity``:
  the rotation about ``initial.center``, by default the body's centre of mass c, as in
  :mod:`fem_anim.simulation.initial_state` (v_0 = v + omega x (X - c));
* the initial displacement ``initial.displacement`` (m; d components) and a body's
  ``body.NAME.initial.displacement``: a rigid translation u_0 of the body's unpinned nodes
  at t = 0. It is not a scene key (scenes start at the rest shape): its value at the scene
  is 0, and the forward run of the adjoint starts from u_0.

* a handle's velocity ``pin.NAME.velocity`` (m/s; d components) of a ``[[pin]]`` that
  moves in the scene (``velocity`` or ``angular_velocity`` given; a body's pin:
  ``body.B.pin.NAME.velocity``): its prescribed displacement at t is the rotation part plus
  velocity min(t, until), so d u_D(t)/d velocity_i = min(t, until) e_i on the pin's nodes
  (and, with Newmark, whose pinned v and a are the handle's exact rates, dv/d velocity_i
  = e_i while it moves);
* the friction coefficients: ``obstacle.NAME.friction`` (mu of the ``[[obstacle]]`` named
  NAME) and ``contact.friction`` (IPC's mu), each positive in the scene (with mu = 0 the
  step has no friction term).

How they are bound into the step objective: :mod:`fem_anim.adjoint.parameters`.
"""

from __future__ import annotations

from fem_anim.errors import FemAnimError

__all__ = ["DAMPING_KEYS", "DISPLACEMENT_KEY", "INITIAL_KEYS", "IPC_FRICTION_KEY",
           "MATERIAL_KEYS", "SPIN_KEY", "VELOCITY_KEY", "component", "components",
           "expand_keys", "handle_prefix", "is_obstacle_friction", "split_group"]

#: Material parameters: key -> the key inside ``[material]`` (after a group's prefix).
MATERIAL_KEYS = {"material.youngs_modulus": "youngs_modulus",
                 "material.poisson_ratio": "poisson_ratio",
                 "material.density": "density"}
#: The Rayleigh damping coefficients: scene key -> the key inside ``[damping]``.
DAMPING_KEYS = {"damping.alpha": "alpha", "damping.beta": "beta"}
#: The rigid initial velocity (one parameter per component).
VELOCITY_KEY = "initial.velocity"
#: The initial spin about the centre (one parameter per component; one number in 2D).
SPIN_KEY = "initial.angular_velocity"
#: The initial rigid translation (one parameter per component; not a scene key).
DISPLACEMENT_KEY = "initial.displacement"
#: The initial-state parameters (vectors of a body or of the scene).
INITIAL_KEYS = (VELOCITY_KEY, SPIN_KEY, DISPLACEMENT_KEY)
#: IPC's friction coefficient (an obstacle's: ``obstacle.NAME.friction``).
IPC_FRICTION_KEY = "contact.friction"


def handle_prefix(key: str) -> str | None:
    """``pin.NAME.`` or ``body.B.pin.NAME.`` of a handle-velocity key (with or without a
    component), else None."""
    base = component(key)[0]
    if not base.endswith(".velocity"):
        return None
    head = base[: -len("velocity")]
    if head.startswith("pin.") and len(head) > len("pin.."):
        return head
    if head.startswith("body.") and ".pin." in head and not head.endswith(".pin."):
        return head
    return None


def is_obstacle_friction(key: str) -> bool:
    """Whether a key names an ``[[obstacle]]``'s friction coefficient."""
    return key.startswith("obstacle.") and key.endswith(".friction") and \
        len(key) > len("obstacle..friction")


def components(base: str, d: int) -> int:
    """How many scalars an initial-state key has: d, and for the spin 1 in 2D, 3 in 3D."""
    if base == SPIN_KEY:
        return 1 if d == 2 else 3
    return d


def component(rest: str) -> tuple[str, int | None]:
    """``initial.velocity[1]`` -> (``initial.velocity``, 1); no index: (rest, None);
    a malformed index: (rest, -1)."""
    if rest.endswith("]") and "[" in rest:
        base, _, index = rest[:-1].partition("[")
        return base, int(index) if index.isdigit() else -1
    return rest, None


def split_group(key: str) -> tuple[str, str]:
    """(group prefix, rest) of a key: ``body.left.material.density`` ->
    (``body.left.``, ``material.density``); ``material.density`` -> ("", itself)."""
    if key.startswith(("body.", "region.")):
        for tail in (".material.", ".initial."):
            at = key.find(tail)
            if at > 0:
                return key[: at + 1], key[at + 1:]
    return "", key


def valid_index(index: int | None, n: int) -> bool:
    """A component index of a vector of n scalars (None: the whole vector; a 1-vector, the
    2D spin, has no index)."""
    return index is None or (n > 1 and 0 <= index < n)


def scalar_names(key: str, index: int | None, n: int) -> list[str]:
    """The scalar names of a vector key: itself (a component or a 1-vector) or KEY[i]."""
    return [key] if index is not None or n == 1 else [f"{key}[{i}]" for i in range(n)]


def expand_keys(keys: list[str], d: int) -> list[str]:
    """Scalar parameter names from scene keys (``...initial.velocity`` -> its d components).

    Raises:
        FemAnimError: a key that names no differentiable parameter (whether the scene has
            the named body or region is checked by :class:`ParameterSet`).
    """
    names: list[str] = []
    for key in keys:
        prefix, rest = split_group(key)
        if rest in MATERIAL_KEYS or (not prefix and rest in DAMPING_KEYS) or \
                key == IPC_FRICTION_KEY or is_obstacle_friction(key):
            names.append(key)
        elif handle_prefix(key) is not None and valid_index(component(key)[1], d):
            names.extend(scalar_names(key, component(key)[1], d))
        elif component(rest)[0] in INITIAL_KEYS and not prefix.startswith("region.") and \
                valid_index(component(rest)[1], components(component(rest)[0], d)):
            base, index = component(rest)
            names.extend(scalar_names(key, index, components(base, d)))
        else:
            known = ", ".join([*MATERIAL_KEYS, *DAMPING_KEYS, *INITIAL_KEYS,
                               "body.NAME.material.KEY", "region.NAME.material.KEY",
                               "body.NAME.initial.velocity", "body.NAME.initial.angular_velocity",
                               "body.NAME.initial.displacement", "pin.NAME.velocity",
                               "body.NAME.pin.P.velocity", "obstacle.NAME.friction",
                               IPC_FRICTION_KEY])
            raise FemAnimError(f"--param {key}: not a parameter this scene can differentiate "
                               f"(one of {known})")
    if len(set(names)) != len(names):
        raise FemAnimError(f"--param: a parameter is named twice in {', '.join(keys)}")
    return names
