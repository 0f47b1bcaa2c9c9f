"""fem_anim: variational implicit time stepping of hyperelastic solids with DOLFINx and PETSc.

Each time step is the minimisation x_{n+1} = argmin 1/2 ||x - y||_M^2 + w E(x) (seed section
3.1). From Python: make a :class:`Scene` (``Scene.load(path)``, ``Scene.from_toml(text)``,
``Scene.from_dict(d)``), :func:`run` it, and read the :class:`Run` (``run.times``,
``run.displacement(frame)``, ``run.stats``, ``run.energy``, ``run.summary``); read an earlier
run with :func:`open_run`; drive the step loop yourself with :class:`Simulation`; differentiate
an objective of the motion with :func:`gradient` (:mod:`.adjoint`).

The package is in concept folders, imported in this order: :mod:`.scene` -> :mod:`.mesh` ->
:mod:`.problem` (energies from ``fem_anim.forms``) -> :mod:`.contact` -> :mod:`.solver` ->
:mod:`.simulation` -> :mod:`.output` -> :mod:`.render`, with :mod:`.cli` on top;
``fem_anim.reference`` is an independent numpy implementation used as test oracle. Its names
are imported on first use: ``import fem_anim`` loads neither DOLFINx nor PETSc.
"""

from fem_anim.lazy_exports import lazy_exports

__version__ = "0.1.0"
_all, __getattr__, _dir = lazy_exports(__name__, {
    "Scene": "scene.loading",
    "run": "runs",
    "open_run": "runs",
    "Run": "runs",
    "Simulation": "simulation.loop",
    "gradient": "adjoint.differentiate",
    "SceneError": "errors",
    "FemAnimError": "errors",
    "ConvergenceError": "errors",
    "Interrupted": "errors",
})
__all__ = ["__version__", *_all]


def __dir__() -> list[str]:
    return __all__
