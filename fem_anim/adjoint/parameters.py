"""What can be differentiated, and how it is bound into the step objective (seed eq. 4).

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
  ``body.NAME.initial.velocity``.

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
:func:`fem_anim.simulation.initial_state.initial_velocity`.

Constants of the contact terms are not parameters: an obstacle's barrier stiffness
(default: the scene's ``material.youngs_modulus`` when the problem is built) and d_hat, and
IPC's kappa and d_hat, are held fixed (:mod:`fem_anim.adjoint.backward`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.errors import FemAnimError
from fem_anim.forms.gravity import gravity_potential
from fem_anim.forms.lame import lame_parameters

__all__ = ["DAMPING_KEYS", "MATERIAL_KEYS", "VELOCITY_KEY", "ParameterSet", "expand_keys",
           "refresh_constant_terms"]

#: Material parameters: key -> the key inside ``[material]`` (after a group's prefix).
MATERIAL_KEYS = {"material.youngs_modulus": "youngs_modulus",
                 "material.poisson_ratio": "poisson_ratio",
                 "material.density": "density"}
#: The Rayleigh damping coefficients: scene key -> the key inside ``[damping]``.
DAMPING_KEYS = {"damping.alpha": "alpha", "damping.beta": "beta"}
#: The rigid initial velocity (one parameter per component).
VELOCITY_KEY = "initial.velocity"


def _split_group(key: str) -> tuple[str, str]:
    """(group prefix, rest) of a key: ``body.left.material.density`` ->
    (``body.left.``, ``material.density``); ``material.density`` -> ("", itself)."""
    if key.startswith(("body.", "region.")):
        for tail in (".material.", "." + VELOCITY_KEY):
            at = key.find(tail)
            if at > 0:
                return key[: at + 1], key[at + 1:]
    return "", key


def expand_keys(keys: list[str], d: int) -> list[str]:
    """Scalar parameter names from scene keys (``...initial.velocity`` -> its d components).

    Raises:
        FemAnimError: a key that names no differentiable parameter (whether the scene has
            the named body or region is checked by :class:`ParameterSet`).
    """
    names: list[str] = []
    for key in keys:
        prefix, rest = _split_group(key)
        if rest in MATERIAL_KEYS or (not prefix and rest in DAMPING_KEYS):
            names.append(key)
        elif rest == VELOCITY_KEY and not prefix.startswith("region."):
            names.extend(f"{key}[{i}]" for i in range(d))
        elif rest.startswith(VELOCITY_KEY + "[") and rest.endswith("]") and \
                not prefix.startswith("region.") and \
                rest[len(VELOCITY_KEY) + 1:-1].isdigit() and \
                int(rest[len(VELOCITY_KEY) + 1:-1]) < d:
            names.append(key)
        else:
            known = ", ".join([*MATERIAL_KEYS, *DAMPING_KEYS, VELOCITY_KEY,
                               "body.NAME.material.KEY", "region.NAME.material.KEY",
                               "body.NAME.initial.velocity"])
            raise FemAnimError(f"--param {key}: not a parameter this scene can differentiate "
                               f"(one of {known})")
    if len(set(names)) != len(names):
        raise FemAnimError(f"--param: a parameter is named twice in {', '.join(keys)}")
    return names


def refresh_constant_terms(problem, gravity_gradient: fem.Form | None) -> None:
    """Reassemble the step objective's terms kept assembled (the mass and damping matrices,
    gravity's nodal force: :mod:`fem_anim.problem.constant_terms`) after rho, mu, lambda
    or the damping coefficients changed (collective).

    Args:
        problem: The :class:`~fem_anim.problem.objective.EnergyProblem`.
        gravity_gradient: The compiled gradient of the gravity potential (None: no gravity).
    """
    terms = problem.constant_terms
    if terms is None:
        return
    for term, Q in zip(terms.terms, terms.matrices):
        Q.zeroEntries()
        fem_petsc.assemble_matrix(Q, term.hessian_form)
        Q.assemble()
    terms._hessians.clear()  # the summed Hessian: reassembled at its next use
    if gravity_gradient is not None:
        with terms.gradient.localForm() as loc:
            loc.set(0.0)
        fem_petsc.assemble_vector(terms.gradient, gravity_gradient)
        terms.gradient.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)


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
        keys: Scene keys (:func:`expand_keys`).

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
        self._velocity_dofs: dict[str, np.ndarray | None] = {"": None}
        self.velocity: dict[str, np.ndarray] = {}
        self._scene_velocity: dict[str, np.ndarray] = {}
        for name in self.names:
            prefix, rest = _split_group(name)
            if rest in MATERIAL_KEYS:
                if prefix not in self._groups:
                    kind, _, group = prefix[:-1].partition(".")
                    raise FemAnimError(f"--param {name}: the scene has no {kind} {group!r}"
                                       if prefix else f"--param {name}: the scene's bodies "
                                       "have their own materials (body.NAME.material...)")
            elif rest in DAMPING_KEYS:
                if not problem.damped:
                    raise FemAnimError(f"--param {name}: the scene has no [damping] section")
            elif rest.startswith(VELOCITY_KEY):
                self._bind_velocity(name, prefix, scene, bodies)
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

    def _bind_velocity(self, name: str, prefix: str, scene, bodies) -> None:
        """The scene's value and dofs of a velocity parameter's group."""
        d = self.problem.d
        if prefix in self.velocity:
            return
        if prefix == "":
            if bodies:
                raise FemAnimError(f"--param {name}: the scene's bodies have their own "
                                   "initial velocities (body.NAME.initial.velocity)")
            cfg = scene.get("initial")
            if cfg is None:
                raise FemAnimError(f"--param {name}: the scene has no [initial] section")
            dofs = None
        else:
            k = next((k for k, b in enumerate(bodies) if prefix == f"body.{b['name']}."), None)
            if k is None:
                raise FemAnimError(f"--param {name}: the scene has no body "
                                   f"{prefix[5:-1]!r}")
            cfg = bodies[k].get("initial")
            if cfg is None:
                raise FemAnimError(f"--param {name}: body {prefix[5:-1]!r} has no "
                                   "[body.initial] section")
            cells = np.flatnonzero(self.problem.cell_body == k).astype(np.int32)
            dofs = compat.dofs_of_cells(self.problem.V, cells)
        value = np.zeros(d) if cfg.get("velocity") is None else \
            np.asarray(cfg["velocity"], dtype=float)
        self.velocity[prefix] = value.copy()
        self._scene_velocity[prefix] = value.copy()
        self._velocity_dofs[prefix] = dofs

    # -- values -------------------------------------------------------------------------
    def _slot(self, name: str):
        """(kind, group or prefix, index) of a parameter."""
        prefix, rest = _split_group(name)
        if rest in MATERIAL_KEYS:
            return "material", self._groups[prefix], \
                ("youngs_modulus", "poisson_ratio", "density").index(MATERIAL_KEYS[rest])
        if rest in DAMPING_KEYS:
            return "damping", None, DAMPING_KEYS[rest]
        return "velocity", prefix, int(rest[len(VELOCITY_KEY) + 1:-1])

    def values(self) -> np.ndarray:
        """The current parameter values, in the order of :attr:`names`."""
        out = []
        for name in self.names:
            kind, where, i = self._slot(name)
            out.append(self.table[where, i] if kind == "material" else
                       self.damping[i] if kind == "damping" else self.velocity[where][i])
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
            else:
                self.velocity[where][i] = float(value)
        E, nu, rho = self.table.T
        if not (np.all((-1.0 < nu) & (nu < 0.5)) and np.all(E > 0.0) and np.all(rho > 0.0)):
            raise FemAnimError(f"parameters out of range: E = {E.tolist()} Pa, "
                               f"nu = {nu.tolist()}, density = {rho.tolist()} kg/m^3")
        if any(v < 0.0 for v in self.damping.values()):
            raise FemAnimError(f"parameters out of range: damping {self.damping} is negative")
        self._sync()

    def _sync(self) -> None:
        """Constants (or the problem's DG0 Functions) and their stand-ins from the table,
        and the problem's terms assembled once from them (:func:`refresh_constant_terms`)."""
        mu, lmbda = lame_parameters(self.table[:, 0], self.table[:, 1])
        values = {"mu": np.atleast_1d(mu), "lmbda": np.atleast_1d(lmbda),
                  "rho": self.table[:, 2]}
        values |= {k: np.array([v]) for k, v in self.damping.items()}
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
            refresh_constant_terms(self.problem, self._gravity_gradient)

    def scene_values(self) -> dict:
        """The parameters under their scene keys (an initial velocity as a list)."""
        out: dict = {}
        for name, value in zip(self.names, self.values()):
            kind, where, _ = self._slot(name)
            if kind == "velocity":
                out[where + VELOCITY_KEY] = [float(v) for v in self.velocity[where]]
            else:
                out[name] = float(value)
        return out

    # -- derivatives --------------------------------------------------------------------
    def material_direction(self, name: str) -> MaterialDirection | None:
        """The coefficients and chain-rule factors of a material or damping parameter
        (None: an initial velocity)."""
        kind, where, i = self._slot(name)
        if kind == "damping":
            return MaterialDirection(None, [(i, 1.0)])
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

    def velocity_basis(self, name: str, problem) -> np.ndarray | None:
        """dv_0/dtheta of an initial-velocity component (local dofs; None: not one)."""
        kind, prefix, i = self._slot(name)
        if kind != "velocity":
            return None
        basis = np.zeros((problem.u.x.array.size // problem.d, problem.d))
        dofs = self._velocity_dofs[prefix]
        if dofs is None:
            basis[:, i] = 1.0
        else:
            basis[dofs, i] = 1.0
        basis = basis.reshape(-1)
        for bc in problem.displacement_bcs:
            basis[bc.dof_indices()[0]] = 0.0
        return basis

    def velocity_offset(self, problem) -> np.ndarray:
        """v_0 minus the scene's v_0: the velocity parameters' change (local dofs)."""
        out = np.zeros(problem.u.x.array.size)
        for prefix, value in self.velocity.items():
            for i in range(problem.d):
                delta = value[i] - self._scene_velocity[prefix][i]
                if delta != 0.0:
                    out += delta * self.velocity_basis(
                        f"{prefix}{VELOCITY_KEY}[{i}]", problem)
        return out
