"""Independent numpy/scipy implementation of the seed's P1 FEM discretisation.

The oracle for the test suite: no UFL, no DOLFINx. It follows the seed's pipeline

* :mod:`.tensor` - column-major ``vec`` (eq. (30)), cofactor, polar decomposition;
* :mod:`.materials` - ``psi``, ``P``, ``dP/dF`` of each material model (section 4.4);
* :mod:`.geometry` - ``D_m``, ``D_s``, ``F = D_s D_m^{-1}``, ``w``, ``G_e`` (eqs. (25)-(34));
* :mod:`.box_mesh` - structured box meshes for tests;
* :mod:`.assembly` - global elastic energy, gradient and Hessian (eq. (27));
* :mod:`.mass` - consistent and lumped mass matrices (eqs. (17)-(20)), gravity potential;
* :mod:`.potential` - the potential energy with mass and pins;
* :mod:`.mixed_energy` - the perturbed-Lagrangian (u, p) energy of the mixed formulation
  (P1/P1);
* :mod:`.obstacle_barrier` - the IPC log barrier against a plane or sphere obstacle and its
  lagged friction (vertex rule);
* :mod:`.newton` - Newton with Armijo backtracking (section 3.2);
* :mod:`.time_integrators` - Newmark, implicit Euler, BDF2, symplectic Euler (section 3.1);
* :mod:`.shell_energy` - a P1 shell's membrane and hinge-bending energies, gradients and
  Hessians (hyper-dual numbers; imported as the module, whose name its energy function
  shares).
* :mod:`.shell_kl_energy` - a P2 shell's membrane and Kirchhoff-Love (C0 interior-penalty)
  bending energy, gradient and Hessian (hyper-dual numbers; imported as the module).
"""

from fem_anim.reference.assembly import elastic_energy, elastic_gradient, elastic_hessian
from fem_anim.reference.obstacle_barrier import (
    boundary_facets,
    contact_energy,
    contact_gradient,
    contact_hessian,
    friction_energy,
    friction_gradient,
)
from fem_anim.reference.geometry import (
    cell_dofs,
    cell_volumes,
    deformation_gradient,
    deformed_shape_matrix,
    gradient_operator,
    rest_shape_matrix,
)
from fem_anim.reference.time_integrators import (
    INTEGRATORS,
    State,
    Trajectory,
    bdf2_step,
    implicit_euler_step,
    initial_state,
    newmark_step,
    simulate,
    symplectic_euler_step,
)
from fem_anim.reference.mass import gravity_energy, gravity_gradient, mass_matrix, vertex_masses
from fem_anim.reference.materials import (
    MATERIALS,
    first_piola,
    first_piola_derivative,
    lame_parameters,
    psi,
    stable_neohookean_parameters,
)
from fem_anim.reference.box_mesh import box_mesh
from fem_anim.reference.newton import ConvergenceError, minimize_newton
from fem_anim.reference.potential import EnergyProblem, build_problem

__all__ = [
    "INTEGRATORS",
    "MATERIALS",
    "ConvergenceError",
    "EnergyProblem",
    "State",
    "Trajectory",
    "bdf2_step",
    "boundary_facets",
    "box_mesh",
    "build_problem",
    "cell_dofs",
    "cell_volumes",
    "contact_energy",
    "contact_gradient",
    "contact_hessian",
    "deformation_gradient",
    "deformed_shape_matrix",
    "elastic_energy",
    "elastic_gradient",
    "elastic_hessian",
    "first_piola",
    "friction_energy",
    "friction_gradient",
    "first_piola_derivative",
    "gradient_operator",
    "gravity_energy",
    "gravity_gradient",
    "implicit_euler_step",
    "initial_state",
    "lame_parameters",
    "mass_matrix",
    "minimize_newton",
    "newmark_step",
    "psi",
    "rest_shape_matrix",
    "simulate",
    "stable_neohookean_parameters",
    "symplectic_euler_step",
    "vertex_masses",
]
