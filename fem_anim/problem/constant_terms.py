"""The step objective's terms with a constant Hessian, assembled once.

The step objective g(x) = 1/2 ||x - y||_M^2 + w E(x) (seed eq. 4) has terms whose Hessian
does not depend on x: the inertia term (Hessian M, the mass matrix of seed eqs. 17-20),
Rayleigh damping's dissipation c/2 (x - x_d)^T C (x - x_d) (:mod:`fem_anim.forms.damping`)
and gravity's potential -int rho g . u (linear: gradient the constant nodal force, zero
Hessian). Assembling them with the elastic term at every Newton iteration would cost the
mass integral's quadrature (degree 2k: 4 points per P1 tetrahedron against the elastic
rule's 1) in every objective, residual and Jacobian.

Here each is kept as what it is, assembled once by DOLFINx from the same UFL forms (the
Hessians by ``ufl.derivative`` of the terms):

* a quadratic term 1/2 s (x - a)^T Q (x - a) as its matrix Q, its anchor a (a Function:
  the predictor y, the damping anchor x_d) and its scale s (1, or a Constant: c);
* a linear term w f . x as its gradient f (a vector) and its scale w (a Constant).

Per evaluation they cost matrix-vector products: the value sum 1/2 s z.Qz + w f.x with
z = x - a; the gradient sum s Q z + w f, with z taken at x with its pinned dofs at their
prescribed values (what ``apply_lifting`` does for the assembled terms: the Newton system's
right-hand side for a step that moves the pins there); the Hessian sum s Q, added to the
assembled Jacobian (:meth:`ConstantTerms.add_hessian`) from a matrix with the pinned rows
and columns zeroed, assembled per matrix type and again only when a scale s changes
(adaptive dt changes c).
"""

from __future__ import annotations

from dataclasses import dataclass

from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_anim import compat

__all__ = ["ConstantTerms", "QuadraticTerm"]


@dataclass
class QuadraticTerm:
    """1/2 s (x - a)^T Q (x - a): Q from ``hessian_form``, a = ``anchor``, s = ``scale``
    (None: 1)."""

    hessian_form: fem.Form
    anchor: fem.Function
    scale: fem.Constant | None = None


class ConstantTerms:
    """The quadratic and linear terms of g, applied as matrices and vectors.

    Args:
        terms: The quadratic terms.
        hessian_form: Their summed Hessian (the scales' Constants inside), assembled into
            the Jacobian's type with the pinned rows and columns zeroed.
        bcs: The pins (Dirichlet conditions on the unknown).
        linear: ``(gradient_form, scale)``: a linear term's constant gradient and its
            scale, or None.
    """

    def __init__(self, terms: list[QuadraticTerm], hessian_form: fem.Form, bcs: list,
                 linear: tuple[fem.Form, fem.Constant] | None = None):
        self.terms = terms
        self.hessian_form = hessian_form
        self.bcs = bcs
        self.matrices = []
        for term in terms:
            Q = fem_petsc.assemble_matrix(term.hessian_form)
            Q.assemble()
            self.matrices.append(Q)
        self.gradient = self.linear_scale = None
        if linear is not None:
            form, self.linear_scale = linear
            self.gradient = fem_petsc.assemble_vector(form)
            self.gradient.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self._z = self._Qz = None
        #: the Hessian's matrix per PETSc matrix type, with the scales it was assembled for
        self._hessians: dict[str, tuple[PETSc.Mat, tuple[float, ...]]] = {}

    def _work(self, x: PETSc.Vec) -> tuple[PETSc.Vec, PETSc.Vec]:
        if self._z is None:
            self._z, self._Qz = x.duplicate(), x.duplicate()
        return self._z, self._Qz

    @staticmethod
    def _scale(term: QuadraticTerm) -> float:
        return 1.0 if term.scale is None else float(term.scale.value)

    def value(self, x: PETSc.Vec) -> float:
        """sum 1/2 s (x - a)^T Q (x - a) + w f . x over all ranks (collective)."""
        z, Qz = self._work(x)
        total = 0.0
        for term, Q in zip(self.terms, self.matrices):
            x.copy(z)
            z.axpy(-1.0, compat.petsc_vec(term.anchor))
            Q.mult(z, Qz)
            total += 0.5 * self._scale(term) * z.dot(Qz)
        if self.gradient is not None:
            total += float(self.linear_scale.value) * self.gradient.dot(x)
        return total

    def add_gradient(self, b: PETSc.Vec, x: PETSc.Vec) -> None:
        """b += sum s Q (x~ - a) + w f on owned entries, x~ = x with the pins at their values
        (collective; b's ghost contributions must already be summed)."""
        z, Qz = self._work(x)
        for term, Q in zip(self.terms, self.matrices):
            x.copy(z)
            fem_petsc.set_bc(z, self.bcs)  # x~: the lifting of the assembled terms, exactly
            z.axpy(-1.0, compat.petsc_vec(term.anchor))
            Q.mult(z, Qz)
            b.axpy(self._scale(term), Qz)
        if self.gradient is not None:
            b.axpy(float(self.linear_scale.value), self.gradient)

    def reassemble(self, gradient_form: fem.Form | None = None) -> None:
        """Assemble the terms again after coefficients inside them changed (rho, mu, lambda,
        the damping coefficients: the adjoint's parameters, :mod:`fem_anim.adjoint.parameters`;
        collective).

        Args:
            gradient_form: The linear term's gradient to assemble in place of the one kept
                (gravity's nodal force with the new densities); None: keep it.
        """
        for term, Q in zip(self.terms, self.matrices):
            Q.zeroEntries()
            fem_petsc.assemble_matrix(Q, term.hessian_form)
            Q.assemble()
        self._hessians.clear()  # the summed Hessian: reassembled at its next use
        if gradient_form is not None:
            with self.gradient.localForm() as loc:
                loc.set(0.0)
            fem_petsc.assemble_vector(self.gradient, gradient_form)
            self.gradient.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)

    def add_hessian(self, A: PETSc.Mat, subset: bool = False) -> None:
        """A += sum s Q with the pinned rows and columns of Q zeroed (A assembled; collective).

        Args:
            A: The assembled Jacobian (its pinned rows and columns are the identity's).
            subset: A has nonzeros the forms' pattern does not (contact pairs): add by
                ``SUBSET_NONZERO_PATTERN`` instead of the forms' identical pattern.
        """
        scales = tuple(self._scale(t) for t in self.terms)
        kind = A.getType()
        H, assembled_for = self._hessians.get(kind, (None, None))
        if H is None:
            H = fem_petsc.create_matrix(self.hessian_form, _mat_type(kind))
        if assembled_for != scales:
            H.zeroEntries()
            fem_petsc.assemble_matrix(H, self.hessian_form, self.bcs, 0.0)
            H.assemble()
            self._hessians[kind] = (H, scales)
        structure = PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN if subset else \
            PETSc.Mat.Structure.SAME_NONZERO_PATTERN
        A.axpy(1.0, H, structure)


def _mat_type(petsc_type: str) -> str | None:
    """DOLFINx's ``mat_type`` for a PETSc matrix type (``seqbaij`` -> ``baij``)."""
    for prefix in ("seq", "mpi"):
        if petsc_type.startswith(prefix):
            return petsc_type[len(prefix):]
    return petsc_type
