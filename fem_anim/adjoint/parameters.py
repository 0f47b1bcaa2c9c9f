"""What can be differentiated, and how it is bound into the step objective (seed eq. 4).

A parameter is a scalar named by its scene key: ``material.youngs_modulus`` (E, Pa),
``material.poisson_ratio`` (nu), ``material.density`` (rho, kg/m^3), and the components of
``initial.velocity`` (``initial.velocity[0]``, ... in m/s: the rigid initial velocity; the
key ``initial.velocity`` names all d components). The material constants enter g of seed
eq. 4 through the Lamé parameters mu(E, nu), lambda(E, nu) and rho, which the forward
solver reads as DOLFINx Constants. Constants cannot be differentiated by ``ufl.derivative``,
so :class:`ParameterSet` keeps, for each, a piecewise-constant (DG0) Function with the same
value, and the adjoint's forms are the problem's forms with each Constant replaced by its
Function (``ufl.replace``). The derivative of a form with respect to E is then

    dF/dE = dmu/dE dF/dmu[1] + dlambda/dE dF/dlambda[1]

(``ufl.derivative`` in the direction of the Function equal to one), with
mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu)(1 - 2 nu)) (:mod:`fem_anim.forms.lame`).

The initial velocity enters the first step's predictor only (and Newmark's a_0 through the
damping force): its derivative is the adjoint of v_0 dotted with the rigid field of each
component, zero on pinned dofs as in :func:`fem_anim.simulation.initial_state.initial_velocity`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_anim.errors import FemAnimError
from fem_anim.forms.gravity import gravity_potential
from fem_anim.forms.lame import lame_parameters

__all__ = ["MATERIAL_KEYS", "VELOCITY_KEY", "ParameterSet", "expand_keys",
           "refresh_constant_terms"]

#: Material parameters: scene key -> the key inside ``[material]``.
MATERIAL_KEYS = {"material.youngs_modulus": "youngs_modulus",
                 "material.poisson_ratio": "poisson_ratio",
                 "material.density": "density"}
#: The rigid initial velocity (one parameter per component).
VELOCITY_KEY = "initial.velocity"


def expand_keys(keys: list[str], d: int) -> list[str]:
    """Scalar parameter names from scene keys (``initial.velocity`` -> its d components).

    Raises:
        FemAnimError: a key that names no differentiable parameter.
    """
    names: list[str] = []
    for key in keys:
        if key in MATERIAL_KEYS:
            names.append(key)
        elif key == VELOCITY_KEY:
            names.extend(f"{VELOCITY_KEY}[{i}]" for i in range(d))
        elif key.startswith(VELOCITY_KEY + "[") and key.endswith("]") and \
                key[len(VELOCITY_KEY) + 1:-1].isdigit() and int(key[len(VELOCITY_KEY) + 1:-1]) < d:
            names.append(key)
        else:
            known = ", ".join([*MATERIAL_KEYS, VELOCITY_KEY])
            raise FemAnimError(f"--param {key}: not a parameter this scene can differentiate "
                               f"(one of {known})")
    if len(set(names)) != len(names):
        raise FemAnimError(f"--param: a parameter is named twice in {', '.join(keys)}")
    return names


def refresh_constant_terms(problem, gravity_gradient: fem.Form | None) -> None:
    """Reassemble the step objective's terms kept assembled (the mass and damping matrices,
    gravity's nodal force: :mod:`fem_anim.problem.constant_terms`) after rho, mu or lambda
    changed (collective).

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
    """dF/dtheta = sum of factor * dF/dc[1] over the replaced coefficients c (by name:
    ``"mu"``, ``"lmbda"``, ``"rho"``)."""

    terms: list[tuple[str, float]]


class ParameterSet:
    """The scalar parameters of one problem, their values and their derivatives' directions.

    Args:
        problem: The :class:`~fem_anim.problem.objective.EnergyProblem` (global material:
            ``mu``, ``lmbda``, ``rho`` are Constants).
        scene: Its scene.
        keys: Scene keys (:func:`expand_keys`).

    Raises:
        FemAnimError: a key the scene does not have, or per-region or per-body materials.
    """

    def __init__(self, problem, scene, keys: list[str]):
        self.problem = problem
        self.names = expand_keys(keys, problem.d)
        if problem.material_map is not None:
            raise FemAnimError("gradient: material parameters given per region or per body "
                               "are not differentiable yet; use one [material]")
        if any(n.startswith(VELOCITY_KEY) for n in self.names) and scene.get("initial") is None:
            raise FemAnimError("--param initial.velocity: the scene has no [initial] section")
        mat = scene["material"]
        self.E = float(mat["youngs_modulus"])
        self.nu = float(mat["poisson_ratio"])
        self.density = float(mat["density"])
        init = scene.get("initial") or {}
        self.velocity = np.zeros(problem.d) if init.get("velocity") is None else \
            np.asarray(init["velocity"], dtype=float)
        self.other_velocity = None  # v_0 of the spin part, fixed (no parameter)
        self.one = fem.Function(problem.W0, name="one")
        self.one.x.array[:] = 1.0
        #: Function standing for each Constant in the adjoint's forms
        self.coefficients = {name: fem.Function(problem.W0, name=f"{name}_coefficient")
                             for name in ("mu", "lmbda", "rho")}
        self.replacements = {getattr(problem, name): f
                             for name, f in self.coefficients.items()}
        self._gravity_gradient = None
        if problem.constant_terms is not None and problem.constant_terms.gradient is not None:
            self._gravity_gradient = fem.form(ufl.derivative(
                gravity_potential(problem.u, problem.rho, problem.g, problem.dx_load),
                problem.u, ufl.TestFunction(problem.V)))
        self._sync()

    # -- values -------------------------------------------------------------------------
    def values(self) -> np.ndarray:
        """The current parameter values, in the order of :attr:`names`."""
        out = []
        for name in self.names:
            if name == "material.youngs_modulus":
                out.append(self.E)
            elif name == "material.poisson_ratio":
                out.append(self.nu)
            elif name == "material.density":
                out.append(self.density)
            else:
                out.append(self.velocity[int(name[len(VELOCITY_KEY) + 1:-1])])
        return np.asarray(out, dtype=float)

    def assign(self, theta) -> None:
        """Set the parameters to ``theta`` (the order of :attr:`names`) in the problem.

        Raises:
            FemAnimError: nu outside (-1, 1/2), E or rho not positive.
        """
        for name, value in zip(self.names, np.asarray(theta, dtype=float)):
            if name == "material.youngs_modulus":
                self.E = float(value)
            elif name == "material.poisson_ratio":
                self.nu = float(value)
            elif name == "material.density":
                self.density = float(value)
            else:
                self.velocity[int(name[len(VELOCITY_KEY) + 1:-1])] = float(value)
        if not (-1.0 < self.nu < 0.5 and self.E > 0.0 and self.density > 0.0):
            raise FemAnimError(f"parameters out of range: E = {self.E:g} Pa, nu = {self.nu:g}, "
                               f"density = {self.density:g} kg/m^3")
        self._sync()

    def _sync(self) -> None:
        """Constants and their stand-in Functions from E, nu, rho, and the problem's terms
        assembled once from them (:func:`refresh_constant_terms`)."""
        mu, lmbda = lame_parameters(self.E, self.nu)
        changed = False
        for name, value in (("mu", mu), ("lmbda", lmbda), ("rho", self.density)):
            constant = getattr(self.problem, name)
            changed |= float(constant.value) != value
            constant.value = value
            self.coefficients[name].x.array[:] = value
        if changed:
            refresh_constant_terms(self.problem, self._gravity_gradient)

    def scene_values(self) -> dict:
        """The parameters under their scene keys (``initial.velocity`` as a list)."""
        out: dict = {}
        for name, value in zip(self.names, self.values()):
            if name.startswith(VELOCITY_KEY):
                out[VELOCITY_KEY] = [float(v) for v in self.velocity]
            else:
                out[name] = float(value)
        return out

    # -- derivatives --------------------------------------------------------------------
    def material_direction(self, name: str) -> MaterialDirection | None:
        """The coefficients and chain-rule factors of a material parameter (None: not one)."""
        E, nu = self.E, self.nu
        if name == "material.youngs_modulus":
            return MaterialDirection([("mu", 1.0 / (2.0 * (1.0 + nu))),
                                      ("lmbda",
                                       nu / ((1.0 + nu) * (1.0 - 2.0 * nu)))])
        if name == "material.poisson_ratio":
            dmu = -E / (2.0 * (1.0 + nu) ** 2)
            dlmbda = E * (1.0 + 2.0 * nu * nu) / ((1.0 + nu) * (1.0 - 2.0 * nu)) ** 2
            return MaterialDirection([("mu", dmu), ("lmbda", dlmbda)])
        if name == "material.density":
            return MaterialDirection([("rho", 1.0)])
        return None

    def velocity_basis(self, name: str, problem) -> np.ndarray | None:
        """dv_0/dtheta of an initial-velocity component (local dofs; None: not one)."""
        if not name.startswith(VELOCITY_KEY):
            return None
        i = int(name[len(VELOCITY_KEY) + 1:-1])
        basis = np.zeros((problem.u.x.array.size // problem.d, problem.d))
        basis[:, i] = 1.0
        basis = basis.reshape(-1)
        for bc in problem.displacement_bcs:
            basis[bc.dof_indices()[0]] = 0.0
        return basis
