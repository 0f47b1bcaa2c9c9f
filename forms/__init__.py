"""UFL definitions of the energies and integrators (installed as ``fem_anim.forms``).

Pure UFL functions of F, the displacement and material parameters, so each module reads
like the seed's equations: no mesh, function space or PETSc here.
:mod:`fem_anim.problem.objective` binds them to DOLFINx.

Modules: :mod:`.kinematics` (F, strains, invariants), :mod:`.lame`, one module per material
of seed section 4.4 (:mod:`.linear`, :mod:`.stvk`, :mod:`.corotated`, :mod:`.neohookean`,
:mod:`.stable_neohookean`) with the registry :mod:`.material`; :mod:`.incompressible` (the
perturbed-Lagrangian (u, p) energy of nearly incompressible solids, with
:mod:`.mooney_rivlin`); :mod:`.inertia` (mass and kinetic energy, seed section 4.1),
:mod:`.gravity`, :mod:`.damping` (Rayleigh damping as a potential),
:mod:`.obstacle_contact` (barrier and friction of static obstacles),
:mod:`.shell_membrane`, :mod:`.shell_bending` (a thin shell's energies on a surface; the
P1 hinge) and :mod:`.shell_kirchhoff_love` (P2 Kirchhoff-Love bending, C0 interior penalty),
:mod:`.aerodynamic_drag` (a shell's wind drag as a dissipation potential) and
:mod:`.time_schemes` (the step objective of each integrator, seed section 3.1).
"""

__all__ = ["gravity", "inertia", "integrator", "kinematics", "lame", "material"]
