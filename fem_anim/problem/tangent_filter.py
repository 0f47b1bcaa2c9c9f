"""The filtered Hessian of the step objective: the elastic tangent made positive
semi-definite per quadrature point, and the exact curvature y^T H y along a direction.

``solver.hessian`` picks the Hessian Newton assembles (:mod:`fem_anim.solver.hessian_choice`):
``"exact"`` the ``ufl.derivative`` of the residual; ``"project"`` (clamp) and ``"abs"`` the
Hessian whose elastic part is w int grad(v) : A+ : grad(du) dX with A+ the filtered
d^2 psi / dF^2 (:func:`fem_anim.solver.hessian_modification.filter_tangent`), the convex
terms and obstacle contact exact; ``"trust_region_filter"`` the abs one plus y^T H y for the
trust-region ratio; ``"auto"`` the exact one, with the filtered forms built and compiled at
their first use (a scene that never meets an indefinite Hessian pays no JIT for them).

:class:`TangentFilter` is a part of :class:`~fem_anim.problem.objective.EnergyProblem`.
"""

from __future__ import annotations

import functools
import time

import ufl
from dolfinx import fem
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.forms.kinematics import deformation_gradient
from fem_anim.problem.form_compiler import JIT_OPTIONS, compile_forms
from fem_anim.solver.hessian_modification import FILTERS, project_psd

__all__ = ["FILTERED_MODES", "TangentFilter"]

#: ``solver.hessian`` modes that assemble the elastic Hessian from a filtered tangent.
FILTERED_MODES = ("project", "abs", "trust_region_filter", "auto")

#: Modes whose only Hessian is the filtered one.
ONLY_FILTERED = ("project", "abs", "trust_region_filter")


class TangentFilter:
    """The filtered Hessian forms, their (lazy) compilation, and switching between them."""

    def _choose_hessian_forms(self, terms, jacobian: ufl.Form, ufl_forms: dict) -> ufl.Form:
        """The Jacobian form to compile for ``hessian_mode``; adds the curvature form to
        ``ufl_forms`` (filtered-only modes) or defers both (``auto``)."""
        self.direction = None
        #: auto: the filtered forms, built and compiled at their first use
        self._lazy_filtered = None
        filtered_forms = functools.partial(self._filtered_forms, terms)
        if self.hessian_mode in ONLY_FILTERED:
            extra = filtered_forms()  # the filtered Hessian is the only one
            jacobian = extra.pop("jacobian_filtered")
            ufl_forms |= extra
        elif self.hessian_mode == "auto":
            self._lazy_filtered = filtered_forms
        return jacobian

    def _filtered_forms(self, terms) -> dict[str, ufl.Form]:
        """The Hessian with the elastic tangent filtered (the convex terms exactly; gravity
        is linear) and, for the trust-region ratio's model, y^T H y of the exact Hessian
        along a direction y (``direction``)."""
        du, dv = terms.du, terms.dv
        filtered = self._projected_elastic_hessian(du, dv)
        if not self.split_constant:
            filtered += ufl.derivative(ufl.derivative(terms.convex, self.u, dv), self.u, du)
        if terms.contact_terms is not None:  # exact: not a function of F
            filtered += self.weight * ufl.derivative(ufl.derivative(
                terms.contact_terms, self.u, dv), self.u, du)
        if terms.correction is not None:
            filtered += self.weight * terms.correction
        forms = {"jacobian_filtered": filtered}
        if self.hessian_mode in ("trust_region_filter", "auto"):
            self.direction = fem.Function(self.V, name="newton_direction")
            forms["curvature"] = ufl.derivative(ufl.derivative(
                terms.objective, self.u, self.direction), self.u, self.direction)
        return forms

    def _projected_elastic_hessian(self, du, dv):
        """w int grad(v) : A+ : grad(du), A+ the filtered d^2 psi/dF^2 (clamp or abs, per
        quadrature point: :func:`fem_anim.solver.hessian_modification.filter_tangent`)."""
        d = self.d
        Fv = ufl.variable(deformation_gradient(self.u))
        tangent = ufl.diff(ufl.diff(self._psi(self.u, Fv), Fv), Fv)
        flat = ufl.as_matrix([[tangent[i, j, k, m] for k in range(d) for m in range(d)]
                              for i in range(d) for j in range(d)])
        self.tangent_data = self._quadrature_data(
            "filtered_tangent", flat, project_psd, (d * d, d * d), (d * d, d * d))
        A = self.tangent_data.function  # row i*d + j, column k*d + m, like `flat`

        def flatten(G):
            return ufl.as_vector([G[i, j] for i in range(d) for j in range(d)])

        return self.weight * ufl.inner(flatten(ufl.grad(dv)), ufl.dot(A, flatten(ufl.grad(du)))
                                       ) * self.dx_elastic

    def set_hessian_filter(self, how: str | None) -> None:
        """Assemble the next Hessians exact (``None``) or with the elastic tangent filtered
        per quadrature point (``"clamp"`` or ``"abs"``:
        :func:`fem_anim.solver.hessian_modification.filter_tangent`). Collective the first
        time a filter is asked under ``auto`` (it compiles the filtered forms).

        Raises:
            ValueError: a filter asked of a problem built without the filtered form, or the
                exact Hessian of a mode that has none.
        """
        if how is not None:
            self._compile_filtered()
        if how is None:
            if self.hessian_mode in ONLY_FILTERED:
                raise ValueError(f"solver.hessian = {self.hessian_mode!r} has no exact Hessian")
            self._active_jacobian = self.jacobian_form
        else:
            if self.tangent_data is None:
                raise ValueError(f"solver.hessian = {self.hessian_mode!r} has no filtered "
                                 "Hessian")
            self.tangent_data.evaluate = FILTERS[how]
            self._active_jacobian = self.jacobian_filtered_form or self.jacobian_form
        self.hessian_filter = how

    def _compile_filtered(self) -> None:
        """``auto``: build and compile the filtered Hessian and y^T H y at their first use
        (collective: every rank reaches it at the same Newton iteration)."""
        if self._lazy_filtered is None:
            return
        forms, self._lazy_filtered = self._lazy_filtered(), None
        start = time.perf_counter()
        with compat.jit_locks_released(JIT_OPTIONS):
            compiled = compile_forms(forms)
        self.compile_s += time.perf_counter() - start
        self.jacobian_filtered_form = compiled["jacobian_filtered"]
        self.curvature_form = compiled["curvature"]

    def curvature(self, x: PETSc.Vec, y: PETSc.Vec) -> float:
        """y^T H(x) y with H the exact (unfiltered) Hessian of g, summed over all ranks."""
        self._compile_filtered()
        self.set_state(x)
        direction = compat.petsc_vec(self.direction)
        y.copy(direction)
        direction.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return self.assemble_scalar(self.curvature_form)
