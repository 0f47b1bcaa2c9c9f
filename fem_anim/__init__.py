"""fem_anim: variational implicit time stepping of hyperelastic solids with DOLFINx and PETSc.

Each time step is the minimisation x_{n+1} = argmin 1/2 ||x - y||_M^2 + w E(x)
(seed section 3.1); see README.md for the command line and scene files.

Layout (STYLE rule 1): :mod:`.scene` -> :mod:`.mesh` -> :mod:`.problem` (energies from
``fem_anim.forms``) -> :mod:`.integrator` -> :mod:`.solver` -> :mod:`.output` ->
:mod:`.render`, tied together by :mod:`.simulation` and :mod:`.cli`.
``fem_anim.reference`` is an independent numpy implementation used as test oracle.
"""

__version__ = "0.1.0"
__all__ = ["__version__"]
