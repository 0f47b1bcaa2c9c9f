"""Initial conditions: a rigid initial velocity of the body (scene section ``[initial]``).

The body starts at rest shape (u_0 = 0) with the velocity of a rigid motion,

    v_0(X) = v + omega x (X - c)        (2D: omega x r = omega (-r_y, r_x)),

``v`` = ``initial.velocity``, ``omega`` = ``initial.angular_velocity`` (a number about z in 2D,
a vector in 3D) and ``c`` = ``initial.center``, by default the centre of mass
c = int rho X dV / int rho dV. The field is affine in X, so interpolating it at the dofs
is exact for P1 and P2: the kinetic energy 1/2 v_0^T M v_0 with the consistent mass is
that of the continuum, 1/2 m |v_c|^2 + 1/2 omega . I_c omega (v_c the velocity of the
centre of mass, I_c the inertia tensor about it). Pinned dofs start at rest (the pins
hold them). The integrator's start (Newmark's a_0 = M^-1 (f(u_0) - C v_0), seed eq. 1b)
is computed from this velocity by :meth:`fem_anim.simulation.loop.Simulation.initial_state`.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem

from fem_anim import compat

__all__ = ["center_of_mass", "initial_velocity", "rigid_velocity"]


def center_of_mass(problem, body: int | None = None) -> np.ndarray:
    """c = int rho X dV / int rho dV over the whole mesh, or one body's cells (collective)."""
    mesh = problem.domain.mesh
    X = ufl.SpatialCoordinate(mesh)
    dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": 2})
    rho = problem.rho
    if body is not None:  # rho on the body's cells, 0 elsewhere
        indicator = fem.Function(problem.W0)
        cells = np.flatnonzero(problem.cell_body == body)
        indicator.x.array[compat.cell_dofs(problem.W0)[cells, 0]] = 1.0
        rho = rho * indicator
    mass = problem.assemble_scalar(fem.form(rho * dx))
    moments = [problem.assemble_scalar(fem.form(rho * X[i] * dx))
               for i in range(problem.d)]
    return np.asarray(moments) / mass


def rigid_velocity(X: np.ndarray, velocity, omega, center) -> np.ndarray:
    """v + omega x (X - c) at the points ``X`` (n, d); ``omega`` a number in 2D."""
    d = X.shape[1]
    r = X - np.asarray(center, dtype=float)
    v = np.zeros_like(X) + (0.0 if velocity is None else np.asarray(velocity, dtype=float))
    if omega is None:
        return v
    if d == 2:
        return v + float(omega) * np.stack([-r[:, 1], r[:, 0]], axis=1)
    return v + np.cross(np.asarray(omega, dtype=float), r)


def initial_velocity(scene, problem) -> np.ndarray | None:
    """v_0 on the local dofs (owned and ghost) from ``[initial]`` (or each ``[[body]]``'s
    ``initial``, about its own centre of mass), or None without any.

    Collective when a centre of mass has to be computed.
    """
    bodies = scene.get("body") or []
    entries = [(None, scene.get("initial"))] if not bodies else \
        [(k, b.get("initial")) for k, b in enumerate(bodies)]
    if all(cfg is None for _, cfg in entries):
        return None
    X = problem.V.tabulate_dof_coordinates()[:, : problem.d]
    v = np.zeros_like(X)
    for body, cfg in entries:
        if cfg is None:
            continue
        center = cfg["center"]
        if center is None:
            center = center_of_mass(problem, body) if cfg["angular_velocity"] is not None \
                else np.zeros(problem.d)
        dofs = slice(None)
        if body is not None:
            cells = np.flatnonzero(problem.cell_body == body).astype(np.int32)
            dofs = compat.dofs_of_cells(problem.V, cells)
        v[dofs] = rigid_velocity(X[dofs], cfg["velocity"], cfg["angular_velocity"], center)
    for bc in problem.displacement_bcs:
        v.reshape(-1)[bc.dof_indices()[0]] = 0.0
    return v.reshape(-1)
