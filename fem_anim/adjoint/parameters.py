"""How the parameters (:mod:`fem_anim.adjoint.parameter_keys`: what can be differentiated)
are bound into the step objective (seed eq. 4).

The material constants enter g of seed eq. 4 through the Lamé parameters mu(E, nu),
lambda(E, nu) and rho, per cell. Without regions or bodies the forward solver reads them as
DOLFINx Constants, which ``ufl.derivative`` cannot differentiate, so :class:`ParameterSet`
keeps, for each, a piecewise-constant (DG0) Function with the same value, and the adjoint's
forms are the problem's forms with each Constant replaced by its Function
(``ufl.replace``); with regions or bodies they are DG0 Functions already. Either way the
adjoint assembles the cell-wise derivative dF/dc (``ufl.derivative`` in the direction of
the DG0 test function: one entry per cell, the gradient per cell), and a parameter's
derivative is its sum over the parameter's cells, by the chain rule

    dF/dE = sum over the cells of E's group of (dmu/dE dF/dmu + dlambda/dE dF/dlambda),

with mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu)(1 - 2 nu)) (:mod:`fem_anim.forms.lame`).
The damping coefficients are Constants of the dissipation potential
(:meth:`fem_anim.problem.energy_terms.EnergyTerms._dissipation`), replaced the same way.

The initial velocity enters the first step's predictor only (and Newmark's a_0 through the
damping force): its derivative is the adjoint of v_0 dotted with the rigid field of each
component (on the body's dofs for a body's), zero on pinned dofs as in
:func:`fem_anim.simulation.initial_state.initial_velocity`. v_0 is linear in the spin too:
the field of component i is e_i x (X - c) (2D: (-(y - c_y), x - c_x)). The centre of mass
c = int rho X dV / int rho dV depends on the densities when they differ over a spinning
body: dc/drho_g = int_g (X - c) dV / int rho dV over the cells g of a density parameter
within the body, and dv_0/drho_g = -omega x dc/drho_g (zero for a uniform density). The
initial displacement enters the first step's predictor, the lagged friction's x_n and
Newmark's a_0 through grad E(u_0): its derivative is the adjoint of u_0 dotted with the
translation field of each component.

Friction is linear in mu for fixed lagged quantities (the pressure or normal forces and
the tangent bases at x_n, which do not depend on mu): the lagged potential is
D = mu D_1(x; x_n) (:func:`fem_anim.forms.obstacle_contact.friction_potential`, IPC's
section 5), so dR/dmu = w grad D_1 = w grad D / mu. An obstacle's mu is a Constant of the
friction form, replaced by a DG0 stand-in like the material's; IPC's is
(grad of the barrier and friction) - (grad of the barrier) over mu, from ipctk
(:mod:`fem_anim.adjoint.backward`).

The other constants of the contact terms are not parameters: an obstacle's barrier stiffness
(default: the scene's ``material.youngs_modulus`` when the problem is built) and d_hat, and
IPC's kappa and d_hat, are held fixed (:mod:`fem_anim.adjoint.backward`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem

from fem_anim import compat
from fem_anim.adjoint.parameter_keys import (
    DAMPING_KEYS, DISPLACEMENT_KEY, IPC_FRICTION_KEY, MATERIAL_KEYS, SPIN_KEY,
    VELOCITY_KEY, component, components, expand_keys, handle_prefix, is_obstacle_friction,
    split_group)
from fem_anim.errors import FemAnimError
from fem_anim.forms.gravity import gravity_potential
from fem_anim.forms.lame import lame_parameters
from fem_anim.simulation.initial_state import center_of_mass, rigid_velocity

__all__ = ["MaterialDirection", "ParameterSet"]

@dataclass
class MaterialDirection:
    """dF/dtheta = sum of factor * dF/dc over the cells of material ``group`` and the
    coefficients c (by name: ``"mu"``, ``"lmbda"``, ``"rho"``, ``"alpha"``, ``"beta"``)."""

    group: int | None  # None: every cell
    terms: list[tuple[str, float]]


class ParameterSet:
    """The scalar parameters of one problem, their values and their derivatives' directions.

    Args:
        problem: The :class:`~fem_anim.problem.objective.EnergyProblem`.
        scene: Its scene.
        keys: Scene keys (:func:`~fem_anim.adjoint.parameter_keys.expand_keys`).

    Raises:
        FemAnimError: a key the scene does not have (a body or region it lacks,
            ``[damping]`` or ``[initial]`` missing, ``material.*`` in a scene of bodies).
    """

    def __init__(self, problem, scene, keys: list[str]):
        self.problem = problem
        self.names = expand_keys(keys, problem.d)
        mmap = problem.material_map
        specs = [scene["material"]] if mmap is None else \
            [m._asdict() if hasattr(m, "_asdict") else vars(m) for m in mmap.materials]
        #: E, nu, rho per material group (index as in the problem's material map)
        self.table = np.array([[float(s["youngs_modulus"]), float(s["poisson_ratio"]),
                                float(s["density"])] for s in specs])
        self._groups = self._group_indices(scene)
        bodies = scene.get("body") or []
        #: prefix ("" or ``body.NAME.``) -> (body index or None, its ``initial`` table or None)
        self._entries = {"": (None, scene.get("initial"))} if not bodies else \
            {f"body.{b['name']}.": (k, b.get("initial")) for k, b in enumerate(bodies)}
        self._initial_dofs: dict[str, np.ndarray | None] = {"": None}
        #: (prefix, initial key) -> the current value (an array of its components)
        self.initial: dict[tuple[str, str], np.ndarray] = {}
        self._scene_initial: dict[tuple[str, str], np.ndarray] = {}
        #: Per-node fields added to u_0 and v_0 (local dof arrays; None: none), the Python
        #: API's per-node initial state (:meth:`~fem_anim.adjoint.differentiate.AdjointModel.
        #: set_initial_fields`); zero on pinned dofs
        self.nodal: dict[str, np.ndarray | None] = {"u": None, "v": None}
        #: friction parameter name -> obstacle index ("contact" for IPC's), and its mu
        self._friction_slot: dict[str, int | str] = {}
        #: handle prefix (``pin.NAME.``) -> index in the problem's ``moving_pins``, and the
        #: handle's velocity (current and the scene's)
        self._handle_index: dict[str, int] = {}
        self.handle: dict[str, np.ndarray] = {}
        self._scene_handle: dict[str, np.ndarray] = {}
        self.friction: dict[int | str, float] = {}
        for name in self.names:
            prefix, rest = split_group(name)
            if handle_prefix(name) is not None:
                self._bind_handle(name, handle_prefix(name), scene)
            elif rest in MATERIAL_KEYS:
                if prefix not in self._groups:
                    kind, _, group = prefix[:-1].partition(".")
                    raise FemAnimError(f"--param {name}: the scene has no {kind} {group!r}"
                                       if prefix else f"--param {name}: the scene's bodies "
                                       "have their own materials (body.NAME.material...)")
            elif rest in DAMPING_KEYS:
                if not problem.damped:
                    raise FemAnimError(f"--param {name}: the scene has no [damping] section")
            elif name == IPC_FRICTION_KEY or is_obstacle_friction(name):
                self._bind_friction(name, scene)
            else:
                self._bind_initial(name, prefix, component(rest)[0], bodies)
        self.damping = {k: float(getattr(problem, f"damping_{k}").value)
                        for k in ("alpha", "beta")} if problem.damped else {}
        self.one = fem.Function(problem.W0, name="one")
        self.one.x.array[:] = 1.0
        W0 = problem.W0
        n_cells = problem.cell_body.size
        cell_dofs = compat.cell_dofs(W0).reshape(-1)[:n_cells]
        #: material group per DG0 dof (owned and ghost)
        self.dof_group = np.zeros(self.one.x.array.size, np.int32)
        if mmap is not None:
            self.dof_group[cell_dofs] = mmap.cell_material
        self._cell_dofs = cell_dofs
        self.owned_cells = W0.dofmap.index_map.size_local
        names = ("mu", "lmbda", "rho") + (("alpha", "beta") if problem.damped else ())
        #: The Function standing for each coefficient in the adjoint's forms (the problem's
        #: own DG0 Function when it has one)
        self.coefficients = {}
        self.replacements = {}
        for name in names:
            c = getattr(problem, name if name in ("mu", "lmbda", "rho") else f"damping_{name}")
            if isinstance(c, fem.Function):
                self.coefficients[name] = c
            else:
                f = fem.Function(W0, name=f"{name}_coefficient")
                self.coefficients[name] = f
                self.replacements[c] = f
        for where in self.friction:  # obstacles' mu: Constants of the friction form
            if where != "contact":
                f = fem.Function(W0, name=f"friction{where}_coefficient")
                self.coefficients[f"friction{where}"] = f
                self.replacements[problem.contact.friction_coefficients[where]] = f
        self._gravity_gradient = None
        if problem.constant_terms is not None and problem.constant_terms.gradient is not None:
            self._gravity_gradient = fem.form(ufl.derivative(
                gravity_potential(problem.u, problem.rho, problem.g, problem.dx_load),
                problem.u, ufl.TestFunction(problem.V)))
        self._sync()

    def _group_indices(self, scene) -> dict[str, int]:
        """Key prefix -> material group: "" for ``[material]`` (absent in a scene of
        bodies), ``region.NAME.`` / ``body.NAME.`` / ``body.NAME.region.R.``."""
        out = {} if scene.get("body") else {"": 0}
        if scene.get("body"):
            for k, body in enumerate(scene["body"]):
                out[f"body.{body['name']}."] = k + 1
            k = len(scene["body"])
            for body in scene["body"]:
                for region in body["region"]:
                    k += 1
                    out[f"body.{body['name']}.region.{region['name']}."] = k
        else:
            for i, region in enumerate(scene.get("region") or []):
                out[f"region.{region['name']}."] = i + 1
        return out

    def _bind_handle(self, name: str, prefix: str, scene) -> None:
        """The moving pin of a handle-velocity parameter."""
        from fem_anim.mesh.bodies import body_pins

        if prefix in self._handle_index:
            return
        p = self.problem
        if p.ipc is not None:
            raise FemAnimError(f"--param {name}: a handle's velocity with IPC contact "
                               "([contact]) is not differentiable yet")
        moving, found = 0, []
        for body, _, pin in body_pins(scene):
            label = f"pin.{pin['name']}." if body is None else f"body.{body}.pin.{pin['name']}."
            is_moving = pin["velocity"] is not None or pin["angular_velocity"] != 0
            if label == prefix:
                found.append((moving if is_moving else None, pin))
            moving += is_moving
        if len(found) != 1:
            raise FemAnimError(f"--param {name}: the scene has no pin {prefix[:-1]!r}"
                               if not found else f"--param {name}: {len(found)} pins are "
                               f"named {prefix[:-1]!r}")
        index, pin = found[0]
        if index is None:
            raise FemAnimError(f"--param {name}: pin {pin['name']!r} does not move (give it "
                               "a velocity or angular_velocity to make it a handle)")
        self._handle_index[prefix] = index
        value = np.array(p.moving_pins[index].velocity, dtype=float)
        self.handle[prefix] = value.copy()
        self._scene_handle[prefix] = value.copy()

    def _bind_friction(self, name: str, scene) -> None:
        """The obstacle (or IPC) of a friction parameter; its mu must be positive."""
        p = self.problem
        if name == IPC_FRICTION_KEY:
            if p.ipc is None:
                raise FemAnimError(f"--param {name}: the scene has no [contact] section")
            where, mu = "contact", float(p.ipc.cfg["friction"])
            p.ipc.cfg = dict(p.ipc.cfg)  # the parameter's value, not the scene's table
        else:
            label = name[len("obstacle."):-len(".friction")]
            found = [i for i, ob in enumerate(scene.get("obstacle") or [])
                     if ob["name"] == label]
            if len(found) != 1:
                raise FemAnimError(f"--param {name}: the scene has no obstacle {label!r}"
                                   if not found else f"--param {name}: {len(found)} "
                                   f"obstacles are named {label!r}")
            where, mu = found[0], float(scene["obstacle"][found[0]]["friction"])
        if mu <= 0.0:
            raise FemAnimError(f"--param {name}: the scene's friction is 0 (no friction term "
                               "to differentiate): give it a positive starting value")
        self._friction_slot[name] = where
        self.friction[where] = mu

    def _bind_initial(self, name: str, prefix: str, base: str, bodies) -> None:
        """The scene's value and the dofs of an initial-state parameter's body."""
        d = self.problem.d
        if (prefix, base) in self.initial:
            return
        what = base.partition(".")[2]
        if prefix == "":
            if bodies:
                raise FemAnimError(f"--param {name}: the scene's bodies have their own "
                                   f"initial velocities and displacements (body.NAME.{base})")
        elif prefix not in self._entries:
            raise FemAnimError(f"--param {name}: the scene has no body {prefix[5:-1]!r}")
        body, cfg = self._entries[prefix]
        if cfg is None and base != DISPLACEMENT_KEY:
            raise FemAnimError(f"--param {name}: the scene has no [initial] section" if
                               prefix == "" else f"--param {name}: body {prefix[5:-1]!r} has "
                               "no [body.initial] section")
        if prefix not in self._initial_dofs:
            cells = np.flatnonzero(self.problem.cell_body == body).astype(np.int32)
            self._initial_dofs[prefix] = compat.dofs_of_cells(self.problem.V, cells)
        n = components(base, d)
        scene_value = None if cfg is None or base == DISPLACEMENT_KEY else cfg.get(what)
        value = np.zeros(n) if scene_value is None else \
            np.atleast_1d(np.asarray(scene_value, dtype=float))
        self.initial[prefix, base] = value.copy()
        self._scene_initial[prefix, base] = value.copy()

    # -- values -------------------------------------------------------------------------
    def _slot(self, name: str):
        """(kind, group or prefix, index) of a parameter."""
        prefix, rest = split_group(name)
        if rest in MATERIAL_KEYS:
            return "material", self._groups[prefix], \
                ("youngs_modulus", "poisson_ratio", "density").index(MATERIAL_KEYS[rest])
        if rest in DAMPING_KEYS:
            return "damping", None, DAMPING_KEYS[rest]
        if name in self._friction_slot:
            return "friction", self._friction_slot[name], 0
        if handle_prefix(name) is not None:
            return "handle", handle_prefix(name), component(name)[1]
        base, index = component(rest)
        return "initial", (prefix, base), 0 if index is None else index

    def values(self) -> np.ndarray:
        """The current parameter values, in the order of :attr:`names`."""
        out = []
        for name in self.names:
            kind, where, i = self._slot(name)
            out.append(self.table[where, i] if kind == "material" else
                       self.damping[i] if kind == "damping" else
                       self.friction[where] if kind == "friction" else
                       self.handle[where][i] if kind == "handle" else self.initial[where][i])
        return np.asarray(out, dtype=float)

    def assign(self, theta) -> None:
        """Set the parameters to ``theta`` (the order of :attr:`names`) in the problem.

        Raises:
            FemAnimError: nu outside (-1, 1/2), E or rho not positive, a damping
                coefficient negative.
        """
        for name, value in zip(self.names, np.asarray(theta, dtype=float)):
            kind, where, i = self._slot(name)
            if kind == "material":
                self.table[where, i] = float(value)
            elif kind == "damping":
                self.damping[i] = float(value)
            elif kind == "friction":
                self.friction[where] = float(value)
            elif kind == "handle":
                self.handle[where][i] = float(value)
            else:
                self.initial[where][i] = float(value)
        E, nu, rho = self.table.T
        if not (np.all((-1.0 < nu) & (nu < 0.5)) and np.all(E > 0.0) and np.all(rho > 0.0)):
            raise FemAnimError(f"parameters out of range: E = {E.tolist()} Pa, "
                               f"nu = {nu.tolist()}, density = {rho.tolist()} kg/m^3")
        if any(v < 0.0 for v in self.damping.values()):
            raise FemAnimError(f"parameters out of range: damping {self.damping} is negative")
        if any(v <= 0.0 for v in self.friction.values()):
            raise FemAnimError(f"parameters out of range: friction {self.friction} is not "
                               "positive")
        self._sync()

    def _sync(self) -> None:
        """Constants (or the problem's DG0 Functions) and their stand-ins from the table,
        and the problem's terms assembled once from them
        (:meth:`~fem_anim.problem.constant_terms.ConstantTerms.reassemble`)."""
        mu, lmbda = lame_parameters(self.table[:, 0], self.table[:, 1])
        values = {"mu": np.atleast_1d(mu), "lmbda": np.atleast_1d(lmbda),
                  "rho": self.table[:, 2]}
        values |= {k: np.array([v]) for k, v in self.damping.items()}
        values |= {f"friction{k}": np.array([v]) for k, v in self.friction.items()
                   if k != "contact"}
        if "contact" in self.friction:
            self.problem.ipc.cfg["friction"] = self.friction["contact"]
        for prefix, index in self._handle_index.items():
            self.problem.moving_pins[index].velocity[:] = self.handle[prefix]
        changed = False
        for name, table in values.items():
            f = self.coefficients[name]
            new = table[self.dof_group] if table.size > 1 else np.full(f.x.array.size, table[0])
            changed |= not np.array_equal(f.x.array, new)
            f.x.array[:] = new
            constant = next((c for c, g in self.replacements.items() if g is f), None)
            if constant is not None:
                changed |= float(constant.value) != table[0]
                constant.value = table[0]
        if changed:
            if self.problem.constant_terms is not None:
                self.problem.constant_terms.reassemble(self._gravity_gradient)

    def scene_values(self) -> dict:
        """The parameters under their scene keys (an initial-state vector as a list; the 2D
        spin as a number)."""
        out: dict = {}
        for name, value in zip(self.names, self.values()):
            kind, where, _ = self._slot(name)
            if kind == "handle":
                out[where + "velocity"] = [float(v) for v in self.handle[where]]
            elif kind == "initial":
                vector = [float(v) for v in self.initial[where]]
                out[where[0] + where[1]] = vector[0] if components(where[1], self.problem.d) \
                    == 1 else vector
            else:
                out[name] = float(value)
        return out

    # -- derivatives --------------------------------------------------------------------
    def material_direction(self, name: str) -> MaterialDirection | None:
        """The coefficients and chain-rule factors of a material or damping parameter
        (None: an initial-state parameter)."""
        kind, where, i = self._slot(name)
        if kind == "damping":
            return MaterialDirection(None, [(i, 1.0)])
        if kind == "friction":  # IPC's: None (fem_anim.adjoint.backward adds it)
            return None if where == "contact" else \
                MaterialDirection(None, [(f"friction{where}", 1.0)])
        if kind != "material":
            return None
        E, nu, _ = self.table[where]
        group = where if self.problem.material_map is not None else None
        if i == 0:
            return MaterialDirection(group, [("mu", 1.0 / (2.0 * (1.0 + nu))),
                                             ("lmbda", nu / ((1.0 + nu) * (1.0 - 2.0 * nu)))])
        if i == 1:
            dmu = -E / (2.0 * (1.0 + nu) ** 2)
            dlmbda = E * (1.0 + 2.0 * nu * nu) / ((1.0 + nu) * (1.0 - 2.0 * nu)) ** 2
            return MaterialDirection(group, [("mu", dmu), ("lmbda", dlmbda)])
        return MaterialDirection(group, [("rho", 1.0)])

    def cell_mask(self, group: int | None) -> np.ndarray:
        """The owned DG0 dofs (cells) of a material group (None: all)."""
        owned = self.dof_group[: self.owned_cells]
        return np.ones(owned.size, bool) if group is None else owned == group

    def centre(self, prefix: str) -> np.ndarray:
        """The centre of an entry's spin: its ``initial.center``, else the centre of mass of
        the body (or mesh) at the current densities (collective)."""
        body, cfg = self._entries[prefix]
        if cfg is not None and cfg.get("center") is not None:
            return np.asarray(cfg["center"], dtype=float)
        return center_of_mass(self.problem, body)

    def omega(self, prefix: str) -> np.ndarray:
        """An entry's current spin (the scene's, or the parameters'), as a vector (3D) or
        a 1-vector (2D)."""
        if (prefix, SPIN_KEY) in self.initial:
            return self.initial[prefix, SPIN_KEY]
        cfg = self._entries[prefix][1]
        value = None if cfg is None else cfg.get("angular_velocity")
        return np.zeros(components(SPIN_KEY, self.problem.d)) if value is None else \
            np.atleast_1d(np.asarray(value, dtype=float))

    def _field(self, prefix: str, values: np.ndarray) -> np.ndarray:
        """A nodal field (n_nodes, d) on an entry's dofs, flattened, zero on pinned dofs."""
        p = self.problem
        out = np.zeros((p.u.x.array.size // p.d, p.d))
        dofs = self._initial_dofs[prefix]
        if dofs is None:
            out[:] = values
        else:
            out[dofs] = values if np.ndim(values) == 1 else values[dofs]
        out = out.reshape(-1)
        for bc in p.displacement_bcs:
            out[bc.dof_indices()[0]] = 0.0
        return out

    def _spin_field(self, prefix: str, omega, centre) -> np.ndarray:
        """omega x (X - c) at the nodes (2D: omega (-(y - c_y), x - c_x)); flattened,
        on the entry's unpinned dofs."""
        X = self.problem.V.tabulate_dof_coordinates()[:, : self.problem.d]
        return self._field(prefix, rigid_velocity(X, None, omega if self.problem.d == 3
                                                  else float(omega[0]), centre))

    def initial_bases(self, name: str, problem) -> list[tuple[str, np.ndarray]]:
        """The derivatives of the initial state by a parameter (collective): a list of
        (``"u"`` or ``"v"``, du_0/dtheta or dv_0/dtheta as local dof arrays); empty for a
        parameter the initial state does not depend on."""
        kind, where, i = self._slot(name)
        if kind == "material" and i == 2:
            return self._centre_bases(where)
        if kind != "initial":
            return []
        prefix, base = where
        unit = np.zeros(components(base, problem.d))
        unit[i] = 1.0
        if base == VELOCITY_KEY:
            return [("v", self._field(prefix, unit))]
        if base == DISPLACEMENT_KEY:
            return [("u", self._field(prefix, unit))]
        return [("v", self._spin_field(prefix, unit, self.centre(prefix)))]

    def _centre_bases(self, group: int) -> list[tuple[str, np.ndarray]]:
        """dv_0/drho_g through the centres of mass of the spinning entries without a given
        centre: -omega x dc/drho_g, dc/drho_g = int_(g in body) (X - c) dV / int_body rho dV
        (collective; every rank takes the same branches)."""
        p = self.problem
        group = group if p.material_map is not None else None
        out = []
        for prefix, (body, cfg) in self._entries.items():
            omega = self.omega(prefix)
            if not np.any(omega) or (cfg is not None and cfg.get("center") is not None):
                continue
            in_body = np.ones(p.cell_body.size, bool) if body is None else p.cell_body == body
            in_group = in_body & (True if group is None else
                                  self.dof_group[self._cell_dofs] == group)
            indicator, body_rho = fem.Function(p.W0), fem.Function(p.W0)
            indicator.x.array[self._cell_dofs[in_group]] = 1.0
            body_rho.x.array[self._cell_dofs[in_body]] = 1.0
            mesh = p.domain.mesh
            X = ufl.SpatialCoordinate(mesh)
            dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": 2})
            c = self.centre(prefix)
            mass = p.assemble_scalar(fem.form(p.rho * body_rho * dx))
            volume = p.assemble_scalar(fem.form(indicator * dx))  # c kept out of the forms:
            dc = (np.array([p.assemble_scalar(fem.form(indicator * X[k] * dx))  # one JIT
                            for k in range(p.d)]) - c * volume) / mass
            # v_0 = omega x (X - c): dv_0 = omega x (-dc), the same at every node
            shift = rigid_velocity(-dc[None, :], None, omega if p.d == 3 else float(omega[0]),
                                   np.zeros(p.d))[0]
            out.append(("v", self._field(prefix, shift)))
        return out

    @property
    def handle_names(self) -> list[str]:
        """The handle-velocity parameters."""
        return [n for n in self.names if handle_prefix(n) is not None]

    def handle_dofs(self) -> np.ndarray:
        """The local dofs (all components) of the handles' nodes (all moving pins)."""
        d = self.problem.d
        nodes = [m.dofs for m in self.problem.moving_pins] + [np.empty(0, np.int32)]
        nodes = np.concatenate(nodes).astype(np.int64)
        return (nodes[:, None] * d + np.arange(d)).reshape(-1)

    def handle_bases(self, name: str, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(d u_D(t)/dtheta, d v_D(t)/dtheta) of a handle-velocity component at time t on
        the handle's nodes (local dof arrays): min(t, until) e_i, and e_i while the handle
        moves (the test of :meth:`fem_anim.problem.handles.PinMotion.rates`)."""
        _, prefix, i = self._slot(name)
        motion = self.problem.moving_pins[self._handle_index[prefix]]
        d = self.problem.d
        disp = np.zeros((self.problem.u.x.array.size // d, d))
        rate = np.zeros_like(disp)
        disp[motion.dofs, i] = min(t, motion.until)
        if t < motion.until * (1.0 - 1e-12):
            rate[motion.dofs, i] = 1.0
        return disp.reshape(-1), rate.reshape(-1)

    def velocity_offset(self, problem) -> np.ndarray:
        """v_0 minus the scene's v_0: the velocity and spin parameters' change (local dofs;
        collective: a spin's centre of mass)."""
        out = np.zeros(problem.u.x.array.size)
        for (prefix, base), value in self.initial.items():
            delta = value - self._scene_initial[prefix, base]
            if base == VELOCITY_KEY and np.any(delta):
                out += self._field(prefix, delta)
            elif base == SPIN_KEY and np.any(delta):
                out += self._spin_field(prefix, delta, self.centre(prefix))
        return out if self.nodal["v"] is None else out + self.nodal["v"]

    def displacement_offset(self, problem) -> np.ndarray:
        """u_0: the initial displacement parameters' translations (local dofs)."""
        out = np.zeros(problem.u.x.array.size)
        for (prefix, base), value in self.initial.items():
            if base == DISPLACEMENT_KEY and np.any(value):
                out += self._field(prefix, value)
        return out if self.nodal["u"] is None else out + self.nodal["u"]
