"""Obstacles of a scene bound to DOLFINx: the contact terms and the step bound that guards them.

:class:`ObstacleContact` turns the scene's ``[[obstacle]]`` tables (a ground plane or a
static sphere) into the UFL terms of :mod:`fem_anim.forms.obstacle_contact` over the body's
exterior facets, added to E in the step objective g(x) = 1/2 ||x - y||_M^2 + w E(x) (seed
eq. 4), and keeps every iterate admissible: the barrier is +inf at d <= 0, so

* :meth:`step_bound` gives the largest alpha in (0, 1] such that the trial x - alpha y keeps
  every contact point at no less than :data:`KEEP_FRACTION` of its current distance
  (exact per point: d is linear in alpha for a plane, and |x - c| - r is a convex function
  of alpha for a sphere, bounded by the first root of a quadratic); the solver's line
  search pre-check scales the Newton direction by it, so no trial state ever crosses;
* :meth:`min_distance` is the objective's backstop (g = +inf where some d <= 0).

The contact points are the quadrature points of the contact measure, i.e. exactly where
the barrier is evaluated: for P1 the vertex rule (the boundary vertices), for P2 the
facets' degree-2 Gauss points (the body's boundary between them is not checked). They
are evaluated by a compiled :class:`dolfinx.fem.Expression` at the facet points mapped
into the reference cell, as FFCx maps them for ``ds``, on the cells owning each exterior
facet; minima are reduced over all ranks, so every rank takes the same decision.

A thin shell (a triangle surface in 3D) has no exterior facets to speak of: its contact
points are the vertices of every triangle (the vertex rule over ``dx``, the lumped mass's,
so kappa stays a pressure on the mid-surface's area), and the obstacle is grown by the
shell's half-thickness t / 2 (a plane moved along its normal, a sphere's radius enlarged): d
is the distance of the shell's face, not of its mid-surface
(:mod:`fem_anim.contact.contact_surface`).
"""

from __future__ import annotations

import math

import basix
import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.errors import SceneError
from fem_anim.forms import obstacle_contact as contact_forms

__all__ = ["ObstacleContact", "KEEP_FRACTION", "contact_quadrature"]

#: A step may bring a contact point at most this close, relative to its current distance.
KEEP_FRACTION = 0.1


def contact_quadrature(degree: int, tdim: int) -> tuple[np.ndarray, dict]:
    """Reference facet points and ``ds`` metadata of the contact measure.

    P1: the facet's vertices with equal weights (the vertex rule: each boundary vertex
    gets its share of the boundary area). FFCx 0.5's own ``"vertex"`` scheme takes the
    cell's vertices instead of the facet's for a facet integral, so the rule is passed
    as a custom one. P2: basix's default (symmetric) rule of degree 2.

    Args:
        degree: Lagrange degree of the displacement (1 or 2).
        tdim: Topological dimension of the mesh (2 or 3).

    Returns:
        The reference facet points, (points, tdim - 1), and the ``metadata`` of ``ufl.ds``.
    """
    facet_name = {2: "interval", 3: "triangle"}[tdim]
    facet = compat.basix_cell(facet_name)
    if degree == 1:
        points = basix.geometry(facet)
        weights = np.full(tdim, 1.0 / math.factorial(tdim - 1) / tdim)
        return points, {"quadrature_rule": "custom", "quadrature_degree": 1,
                        "quadrature_points": tuple(map(tuple, points.tolist())),
                        "quadrature_weights": tuple(weights.tolist())}
    points, _ = compat.reference_quadrature(facet_name, 2)
    return points, {"quadrature_rule": "default", "quadrature_degree": 2}


class ObstacleContact:
    """Barrier (and friction) terms of a scene's obstacles, and their admissibility checks.

    Args:
        obstacles: The validated ``[[obstacle]]`` tables.
        u: The displacement Function the energies are taken of.
        u_prev: The displacement at the start of the step (friction's lagged state).
        degree: Lagrange degree of ``u``.
        youngs_modulus: The default of ``obstacle.stiffness``.
        offset: How far from the obstacle the body's surface lies (m): 0 for a solid, half
            the thickness of a shell (whose mesh is its mid-surface).

    Raises:
        SceneError: (collectively) if the rest configuration touches or crosses an obstacle.
    """

    def __init__(self, obstacles: list[dict], u: fem.Function, u_prev: fem.Function,
                 degree: int, youngs_modulus: float, offset: float = 0.0):
        mesh = u.function_space.mesh
        self.comm: MPI.Comm = mesh.comm
        self.obstacles = obstacles
        self.gdim = mesh.geometry.dim
        self.u = u
        self.direction = fem.Function(u.function_space, name="contact_direction")
        #: a shell's contact points are its triangles' vertices (module docstring)
        self.shell = mesh.topology.dim < self.gdim
        points, metadata = contact_quadrature(degree, mesh.topology.dim + self.shell)
        if self.shell:  # the lumped mass's rule: one rule per kernel (FFCx 0.5, shell_rules)
            metadata = {"quadrature_rule": "vertex", "quadrature_degree": 1}
        self.ds = ufl.Measure("dx" if self.shell else "ds", domain=mesh, metadata=metadata)
        self.step_size = fem.Constant(mesh, PETSc.ScalarType(1.0))  # h, for eps_v h
        X = ufl.SpatialCoordinate(mesh)
        self.X = X
        self._distance = []  # per obstacle: UFL d(x) builder and numpy parameters
        for ob in obstacles:
            kappa = ob["stiffness"] if ob["stiffness"] is not None else youngs_modulus
            ob = dict(ob, stiffness=float(kappa))
            if ob["type"] == "plane":
                n = np.asarray(ob["normal"], float)
                n = n / np.linalg.norm(n)
                p = np.asarray(ob["point"] if ob["point"] is not None else [0.0] * self.gdim,
                               float)
                self._distance.append((ob, {"normal": n, "point": p + offset * n}))
            else:
                self._distance.append((ob, {"center": np.asarray(ob["center"], float),
                                            "radius": float(ob["radius"]) + offset}))
        self._setup_points(points)
        self._check_rest()
        #: obstacle index -> its friction coefficient mu (a Constant: the adjoint's parameter
        #: ``obstacle.NAME.friction``), for the obstacles with friction > 0
        self.friction_coefficients: dict[int, fem.Constant] = {}
        self.energy = self._sum(lambda ob, d: contact_forms.contact_energy(
            d(X + u), ob["dhat"], ob["stiffness"], self.ds))
        self.friction = self._sum(lambda ob, d: self._friction(ob, d, u, u_prev), friction=True)

    # -- UFL terms --------------------------------------------------------------------------
    def _ufl_distance(self, i: int):
        ob, geo = self._distance[i]
        if ob["type"] == "plane":
            n, p = ufl.as_vector(geo["normal"].tolist()), ufl.as_vector(geo["point"].tolist())
            return lambda x: contact_forms.plane_distance(x, p, n)
        c = ufl.as_vector(geo["center"].tolist())
        return lambda x: contact_forms.sphere_distance(x, c, geo["radius"])

    def _sum(self, term, friction: bool = False):
        forms = [term(ob, self._ufl_distance(i)) for i, (ob, _) in enumerate(self._distance)
                 if not friction or ob["friction"] > 0]
        return sum(forms[1:], forms[0]) if forms else None

    def _friction(self, ob, distance, u, u_prev):
        """Lagged friction of one obstacle: pressure and normal from x_n = X + u_prev."""
        x_n = self.X + u_prev
        dhat, kappa = ob["dhat"], ob["stiffness"]
        pressure = -kappa / dhat * contact_forms.barrier_derivative(distance(x_n), dhat)
        if ob["type"] == "plane":
            normal = ufl.as_vector(self._geometry(ob)["normal"].tolist())
        else:
            normal = contact_forms.sphere_normal(
                x_n, ufl.as_vector(self._geometry(ob)["center"].tolist()))
        index = next(i for i, (o, _) in enumerate(self._distance) if o is ob)
        mu = self.friction_coefficients[index] = fem.Constant(
            self.u.function_space.mesh, PETSc.ScalarType(ob["friction"]))
        return contact_forms.friction_potential(u, u_prev, normal, pressure, mu,
                                                ob["epsv"] * self.step_size, self.ds)

    def curvature_correction(self, du, dv):
        """The PSD projection of the sphere barriers' Hessian, as a term to add to it.

        The Hessian of kappa/d_hat b(d(x)) is kappa/d_hat [b'' grad d grad d^T + b' Hess d]
        with b' <= 0 and, for a sphere, Hess d = (I - r r^T/|r|^2)/|r| >= 0: its tangential
        eigenvalues kappa/d_hat b'/|r| are negative and, near contact, can make the step
        Hessian indefinite. Adding -kappa/d_hat b' Hess d removes them (IPC's per-contact
        projection); a plane's Hessian is exact and PSD already.

        Args:
            du: The trial function of the Hessian form.
            dv: The test function of the Hessian form.

        Returns:
            The UFL bilinear form to add to the Hessian, or None without spheres.
        """
        terms = []
        for ob, geo in self._distance:
            if ob["type"] != "sphere":
                continue
            r = self.X + self.u - ufl.as_vector(geo["center"].tolist())
            norm = ufl.sqrt(ufl.dot(r, r))
            tangential = du - ufl.dot(r, du) / (norm * norm) * r
            slope = contact_forms.barrier_derivative(norm - geo["radius"], ob["dhat"])
            terms.append(-ob["stiffness"] / ob["dhat"] * slope * ufl.dot(tangential, dv)
                         / norm * self.ds)
        return sum(terms[1:], terms[0]) if terms else None

    def _geometry(self, ob) -> dict:
        return next(geo for o, geo in self._distance if o is ob)

    def stage(self, h: float) -> None:
        """Set the step size h of friction's smoothing length eps_v h.

        Args:
            h: The time step (s).
        """
        self.step_size.value = h

    # -- contact points ---------------------------------------------------------------------
    def _setup_points(self, points: np.ndarray) -> None:
        """Exterior facets, their cells and local indices, and the point Expression."""
        mesh = self.u.function_space.mesh
        tdim = mesh.topology.dim
        cell = compat.basix_cell(mesh.topology.cell_name())
        self.points_per_facet = points.shape[0]
        g = self.gdim
        x = self.X + self.u
        values = ufl.as_vector([x[i] for i in range(g)] + [self.direction[i] for i in range(g)])
        if self.shell:  # every owned triangle, its vertices (the points are the cell's)
            self.cells = np.arange(mesh.topology.index_map(tdim).size_local, dtype=np.int32)
            self.facet_row = np.arange(self.cells.size)
            self.facet_local = np.zeros(self.cells.size, np.int64)
            self.expression = compat.expression(values, points)
            return
        mesh.topology.create_connectivity(tdim - 1, tdim)
        mesh.topology.create_connectivity(tdim, tdim - 1)
        facets = dmesh.exterior_facet_indices(mesh.topology)
        f_to_c = mesh.topology.connectivity(tdim - 1, tdim)
        c_to_f = mesh.topology.connectivity(tdim, tdim - 1)
        cells = f_to_c.array[f_to_c.offsets[facets]]
        local = np.argmax(c_to_f.array.reshape(-1, tdim + 1)[cells] == facets[:, None], axis=1)
        self.cells, inverse = np.unique(cells, return_inverse=True)
        self.cells = self.cells.astype(np.int32)
        self.facet_row, self.facet_local = inverse, local

        geometry = basix.geometry(cell)
        mapped = []
        for vertices in basix.topology(cell)[tdim - 1]:  # FFCx's map_facet_points
            v = geometry[vertices]
            mapped.append(v[0] + points @ (v[1:] - v[0]))
        self.expression = compat.expression(values, np.vstack(mapped))

    def _evaluate(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions x and directions y at every local contact point, (n, gdim) each."""
        g, nq = self.gdim, self.points_per_facet
        if self.cells.size == 0:
            return np.zeros((0, g)), np.zeros((0, g))
        values = compat.evaluate(self.expression, self.u.function_space.mesh, self.cells)
        values = values.reshape(self.cells.size, -1, nq, 2, g)
        values = values[self.facet_row, self.facet_local].reshape(-1, 2, g)
        return values[:, 0], values[:, 1]

    def _distances(self, x: np.ndarray) -> list[np.ndarray]:
        out = []
        for ob, geo in self._distance:
            if ob["type"] == "plane":
                out.append((x - geo["point"]) @ geo["normal"])
            else:
                out.append(np.linalg.norm(x - geo["center"], axis=1) - geo["radius"])
        return out

    def _global_min(self, values: np.ndarray) -> float:
        return self.comm.allreduce(float(values.min()) if values.size else np.inf, op=MPI.MIN)

    def min_distance(self) -> float:
        """Smallest d over every contact point, obstacle and rank (collective).

        Returns:
            The signed distance (m) at the current ``u``; inf without contact points.
        """
        x, _ = self._evaluate()
        return min((self._global_min(d) for d in self._distances(x)), default=np.inf)

    def distances(self) -> list[float]:
        """Smallest d per obstacle over all ranks, for the current ``u`` (collective).

        Returns:
            One distance (m) per obstacle, in scene order.
        """
        x, _ = self._evaluate()
        return [self._global_min(d) for d in self._distances(x)]

    def step_bound(self, y: PETSc.Vec) -> float:
        """Largest alpha <= 1 keeping d(x - alpha y) >= KEEP_FRACTION d(x) at every point.

        Exact per contact point (d is linear in alpha for a plane; for a sphere the first
        root of a quadratic); the minimum is reduced over all ranks (collective).

        Args:
            y: The search direction (the trial point is x - alpha y); ``u`` must hold the
                current iterate x, ghosts updated.

        Returns:
            The step bound alpha in (0, 1], the same on every rank.
        """
        direction = compat.petsc_vec(self.direction)
        with y.localForm() as y_local, direction.localForm() as target:
            y_local.copy(target)
        direction.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        x, y_p = self._evaluate()
        alpha = np.ones(x.shape[0])
        for (ob, geo), d0 in zip(self._distance, self._distances(x)):
            keep = (1.0 - KEEP_FRACTION) * d0
            if ob["type"] == "plane":  # d(alpha) = d0 - alpha n.y
                rate = y_p @ geo["normal"]
                closing = rate > 0
                alpha[closing] = np.minimum(alpha[closing], keep[closing] / rate[closing])
            else:  # |a - alpha b| = r + KEEP_FRACTION d0: first root of a quadratic
                a, b = x - geo["center"], y_p
                rho = geo["radius"] + KEEP_FRACTION * d0
                ab, bb = np.einsum("ij,ij->i", a, b), np.einsum("ij,ij->i", b, b)
                c0 = np.einsum("ij,ij->i", a, a) - rho ** 2
                disc = ab ** 2 - bb * c0
                hit = (ab > 0) & (disc >= 0)
                root = c0[hit] / (ab[hit] + np.sqrt(disc[hit]))
                alpha[hit] = np.minimum(alpha[hit], root)
        return self._global_min(alpha)

    def _check_rest(self) -> None:
        """The rest configuration must lie strictly outside every obstacle (collective)."""
        self.u.x.array[:] = 0.0
        x, _ = self._evaluate()
        mesh = self.u.function_space.mesh
        for i, ((ob, geo), d) in enumerate(zip(self._distance, self._distances(x))):
            dmin = self._global_min(d)
            inside = False
            if ob["type"] == "sphere" and not self.shell:  # a surface has no inside
                inside = self.comm.allreduce(_point_in_mesh(mesh, geo["center"]), op=MPI.LOR)
            if not dmin > 0.0 or inside:
                what = "the sphere's centre lies inside the body" if inside and dmin > 0 else \
                    f"a boundary point of the body is at signed distance {dmin:.3g} m"
                raise SceneError(f"obstacle[{i}] ({ob['name']}): the body's rest configuration "
                                 f"touches or crosses this {ob['type']} ({what}); move the "
                                 "obstacle or the body")


def _point_in_mesh(mesh, point: np.ndarray) -> bool:
    """Whether ``point`` lies in a local cell (DOLFINx's bounding-box tree)."""
    p3 = np.zeros((1, 3))
    p3[0, : point.size] = point
    return compat.colliding_cells(mesh, p3).links(0).size > 0
