"""UFL definitions of the energies and integrators (installed as ``fem_anim.forms``).

Pure UFL functions of F, the displacement and material parameters: no mesh, function
space or PETSc here (STYLE rule 2). :mod:`fem_anim.problem.objective` binds them to DOLFINx.

Modules: :mod:`.kinematics` (F, strains), :mod:`.lame`, one module per material
(:mod:`.linear`, :mod:`.stvk`, :mod:`.corotated`, :mod:`.neohookean`,
:mod:`.stable_neohookean`) with the registry :mod:`.material`; :mod:`.mixed` (the
perturbed-Lagrangian (u, p) energy of nearly incompressible solids, with
:mod:`.mooney_rivlin`); :mod:`.inertia` (mass and kinetic energy), :mod:`.gravity`,
:mod:`.integrator` (step objectives).
"""

__all__ = ["gravity", "inertia", "integrator", "kinematics", "lame", "material"]
