"""The one place that knows which DOLFINx release is installed.

fem_anim runs on Debian's DOLFINx 0.5.2 (Debian 12: UFL 2022.2, FFCx/basix 0.5, PETSc 3.18)
and 0.9.0 (Debian 13: UFL 2024.2, FFCx/basix 0.9, PETSc 3.22). Every name that differs
between them is wrapped here, in the package and in the tests alike
(``tests/test_compat_seam.py`` fails when one appears elsewhere):

::

    ==========================================  ==================================================
    0.5.2                                       0.9.0
    ==========================================  ==================================================
    ``fem.VectorFunctionSpace(mesh, el)``       ``fem.functionspace(mesh, ("Lagrange", k, (d,)))``
    ``fem.FunctionSpace(mesh, ("DG", 0))``      ``fem.functionspace(mesh, ("DG", 0))``
    ``ufl.TensorElement("Quadrature", ...)``    ``basix.ufl.quadrature_element(cell, shape, ...)``
    ``ufl.Mesh(ufl.VectorElement(...))``        ``basix.ufl.element("Lagrange", cell, 1, shape)``
    ``ufl.MixedElement([...])``                 ``basix.ufl.mixed_element([...])``
    ``PC.SchurPreType``                         ``PC.FieldSplitSchurPreType`` (petsc4py)
    ``KSP...CONVERGED_CG_NEG_CURVE`` (5),        ``CONVERGED_NEG_CURVE`` (5),
    ``CONVERGED_CG_CONSTRAINED`` (6)            ``CONVERGED_STEP_LENGTH`` (6) (petsc4py)
    ``u.vector``                                ``u.x.petsc_vec``
    ``geometry.dofmap`` / ``dofmap.list``       2D arrays (0.5: adjacency lists)
    ``geometry.BoundingBoxTree(mesh, d)``       ``geometry.bb_tree(mesh, d)``
    ``compute_collisions(tree, x)``             ``compute_collisions_points(tree, x)``
    ``Expression(e, X, jit_params=)``           ``Expression(e, X, jit_options=)``
    ``Expression.eval(cells)``                  ``Expression.eval(mesh, cells)``
    ``basix.cell.string_to_type``               ``basix.CellType[name]``
    ``make_quadrature(rule, cell, degree)``     ``make_quadrature(cell, degree, rule=...)``
    ``ffcx.get_parameters``, ``parameters=``    ``ffcx.get_options``, ``options=``
    ``fem.FormMetaClass(ufcx, V, w, c, ...)``   ``form_cpp_class(dtype)(ptr, V, w, c, ...)``; ``Form``
    ``ufcx_form.original_coefficient_position`` ``original_coefficient_positions``
    ``set_bc(scale=)``, ``apply_lifting(...)``  ``alpha=`` (fem_anim passes them by position)
    ``create_mesh``: shared-facet ghosts         no ghosts by default (a ``partitioner`` of
                                                ``GhostMode.shared_facet`` for ``dS``)
    FFCx tables of ``grad(grad(u))`` on a        right (FFCx 0.5 counts the reference derivatives
    surface in 3D: wrong index, IndexError      over gdim, not tdim: fixed here on import,
                                                :func:`_fix_manifold_derivative_tables`)
    ==========================================  ==================================================

Each function below branches on :data:`LEGACY` (0.5) against the current API (0.9). A newer
release is one more branch in the functions whose names it changes; DOLFINx 0.10, for
example, renames ``io.gmshio`` to ``io.gmsh`` (fem_anim meshes through the gmsh API
itself and does not use either), wraps SNES in ``fem.petsc.NonlinearProblem`` (fem_anim
drives its own SNES) and merges the blocked assemblers (fem_anim assembles one space).
"""

from __future__ import annotations

import os
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import dolfinx
import ffcx
import ffcx.codegeneration.jit
import numpy as np
import ufl
from dolfinx import cpp as _cpp
from dolfinx import fem, geometry, jit
from dolfinx import mesh as dmesh

__all__ = ["DOLFINX_VERSION", "LEGACY", "SUPPORTED", "vector_space", "cell_space", "mixed_space",
           "collapse_subspace", "set_schur_user_matrix", "trust_region_boundary_reasons",
           "quadrature_space", "petsc_vec", "geometry_dofmap", "cell_dofs", "dofs_of_cells",
           "create_mesh", "colliding_cells", "expression", "evaluate", "basix_cell",
           "reference_quadrature", "compile_forms_together", "jit_locks_released"]

#: (major, minor) of the DOLFINx in use.
DOLFINX_VERSION: tuple[int, int] = tuple(int(p) for p in dolfinx.__version__.split(".")[:2])
#: The DOLFINx series fem_anim is written and tested against.
SUPPORTED = ((0, 5), (0, 9))
if DOLFINX_VERSION not in SUPPORTED:
    raise ImportError(f"fem_anim supports DOLFINx 0.5 and 0.9 (Debian 12 and 13); "
                      f"this is DOLFINx {dolfinx.__version__}")
#: True on DOLFINx 0.5 (Debian 12), False on 0.9 (Debian 13).
LEGACY: bool = DOLFINX_VERSION < (0, 9)


def _fix_manifold_derivative_tables() -> None:
    """Make FFCx 0.5 tabulate second reference derivatives on a manifold (idempotent).

    FFCx 0.5's ``ffcx/ir/elementtables.py`` (``get_modified_terminal_element``, line 224)
    turns a terminal's reference derivative directions into counts over the *geometric*
    dimension, and looks the counts up in basix's table of the *topological* one: on a
    triangle in 3D ``d^2/dxi_1^2`` becomes ``(0, 2, 0)``, basix index 7 of a table of 6
    ("IndexError: index 7 is out of bounds for axis 0 with size 6"); first derivatives
    happen to land on the right index. FFCx 0.9 counts over ``tdim`` (its line 250). The
    counts past ``tdim`` are zero (reference directions are ``< tdim``), so dropping them
    is exactly 0.9's rule; forms without second derivatives on a manifold get the same
    tables, hence the same code, as before. A shell's Kirchhoff-Love bending
    (:mod:`fem_anim.forms.shell_kirchhoff_love`) needs it.
    """
    import ffcx.ir.elementtables as tables

    if getattr(tables, "_fem_anim_tdim_counts", False):
        return
    original = tables.get_modified_terminal_element

    def get_modified_terminal_element(mt):
        result = original(mt)
        if result is None:
            return result
        tdim = mt.terminal.ufl_domain().topological_dimension()
        counts = tuple(result.local_derivatives)
        if len(counts) > tdim:
            assert not any(counts[tdim:])
            result = result._replace(local_derivatives=counts[:tdim])
        return result

    tables.get_modified_terminal_element = get_modified_terminal_element
    tables._fem_anim_tdim_counts = True


if LEGACY:
    _fix_manifold_derivative_tables()

if not LEGACY:
    import basix.ufl
    from dolfinx.fem import forms as _forms


def vector_space(mesh, degree: int) -> fem.FunctionSpace:
    """Vector-valued continuous Lagrange space of the given degree.

    Args:
        mesh: The DOLFINx mesh (its geometric dimension is the value size).
        degree: The Lagrange degree.
    """
    if LEGACY:
        return fem.VectorFunctionSpace(mesh, ("Lagrange", degree))
    return fem.functionspace(mesh, ("Lagrange", degree, (mesh.geometry.dim,)))


def mixed_space(mesh, degree_u: int, degree_p: int) -> fem.FunctionSpace:
    """Mixed space of a vector Lagrange displacement and a scalar Lagrange pressure.

    Args:
        mesh: The DOLFINx mesh.
        degree_u: The displacement's Lagrange degree.
        degree_p: The pressure's Lagrange degree ((2, 1): Taylor-Hood).
    """
    if LEGACY:
        cell = mesh.ufl_cell()
        element = ufl.MixedElement([ufl.VectorElement("Lagrange", cell, degree_u),
                                    ufl.FiniteElement("Lagrange", cell, degree_p)])
        return fem.FunctionSpace(mesh, element)
    cell = mesh.topology.cell_name()
    element = basix.ufl.mixed_element([
        basix.ufl.element("Lagrange", cell, degree_u, shape=(mesh.geometry.dim,)),
        basix.ufl.element("Lagrange", cell, degree_p)])
    return fem.functionspace(mesh, element)


def collapse_subspace(space: fem.FunctionSpace, i: int) -> tuple[fem.FunctionSpace, np.ndarray]:
    """Sub-space ``i`` of a mixed space as a space of its own.

    Args:
        space: The mixed space.
        i: The sub-space's index.

    Returns:
        The collapsed space, and the map from each of its local dofs (unrolled: block size
        times nodes, owned and ghost) to the local dof of the mixed space (int32).
    """
    sub, dofs = space.sub(i).collapse()
    return sub, np.asarray(dofs, dtype=np.int32)


def set_schur_user_matrix(pc, S) -> None:
    """``PCFieldSplitSetSchurPre(pc, USER, S)``.

    petsc4py 3.18 names the enum ``PC.SchurPreType``, later releases
    ``PC.FieldSplitSchurPreType``.

    Args:
        pc: A PCFIELDSPLIT preconditioner of Schur type.
        S: The matrix to precondition the Schur complement with.
    """
    from petsc4py import PETSc

    kinds = getattr(PETSc.PC, "FieldSplitSchurPreType", None) or PETSc.PC.SchurPreType
    pc.setFieldSplitSchurPreType(kinds.USER, S)


def trust_region_boundary_reasons() -> tuple[int, int]:
    """The KSP reasons of a trust-region CG (KSPSTCG) that stopped on the region's boundary:
    negative curvature followed to it, and CG's iterate leaving it. petsc4py 3.18 names them
    ``CONVERGED_CG_NEG_CURVE`` and ``CONVERGED_CG_CONSTRAINED`` (its ``CONVERGED_STEP_LENGTH``
    is 7, another reason), 3.22 ``CONVERGED_NEG_CURVE`` and ``CONVERGED_STEP_LENGTH``.

    Returns:
        The two reasons (negative curvature, boundary reached), 5 and 6 on both releases.
    """
    from petsc4py import PETSc

    R = PETSc.KSP.ConvergedReason
    if hasattr(R, "CONVERGED_CG_NEG_CURVE"):
        return R.CONVERGED_CG_NEG_CURVE, R.CONVERGED_CG_CONSTRAINED
    return R.CONVERGED_NEG_CURVE, R.CONVERGED_STEP_LENGTH


def cell_space(mesh) -> fem.FunctionSpace:
    """Piecewise-constant scalars: one value per cell (DG0).

    Args:
        mesh: The DOLFINx mesh.
    """
    if LEGACY:
        return fem.FunctionSpace(mesh, ("DG", 0))
    return fem.functionspace(mesh, ("DG", 0))


def quadrature_space(mesh, degree: int, shape: tuple[int, ...] = ()) -> fem.FunctionSpace:
    """Quadrature-point data space of the default scheme.

    Args:
        mesh: The DOLFINx mesh.
        degree: The quadrature degree.
        shape: The value shape at each point (``()``: scalars).
    """
    if LEGACY:
        cell = mesh.ufl_cell()
        if shape:
            element = ufl.TensorElement("Quadrature", cell, degree, shape=shape,
                                        quad_scheme="default")
        else:
            element = ufl.FiniteElement("Quadrature", cell, degree, quad_scheme="default")
        return fem.FunctionSpace(mesh, element)
    element = basix.ufl.quadrature_element(mesh.topology.cell_name(), value_shape=tuple(shape),
                                           scheme="default", degree=degree)
    return fem.functionspace(mesh, element)


def petsc_vec(u: fem.Function):
    """The PETSc vector that holds a Function's degrees of freedom.

    Args:
        u: The Function.
    """
    return u.vector if LEGACY else u.x.petsc_vec


def geometry_dofmap(mesh) -> np.ndarray:
    """Cell -> geometry node indices.

    Args:
        mesh: The DOLFINx mesh.

    Returns:
        A (num_cells, nodes_per_cell) array, ghost cells included.
    """
    dofmap = mesh.geometry.dofmap
    if LEGACY:
        return dofmap.array.reshape(dofmap.num_nodes, -1)
    return dofmap


def cell_dofs(V: fem.FunctionSpace) -> np.ndarray:
    """Cell -> dof (block) indices of a space.

    Args:
        V: The function space.

    Returns:
        A (num_cells, dofs_per_cell) array, ghost cells included.
    """
    dofmap = V.dofmap.list
    if LEGACY:
        return dofmap.array.reshape(dofmap.num_nodes, -1)
    return dofmap


def dofs_of_cells(V: fem.FunctionSpace, cells: np.ndarray) -> np.ndarray:
    """The (block) dofs of the given local cells, sorted and unique.

    ``fem.locate_dofs_topological(V, tdim, cells)`` does this on 0.5, but on 0.9 it asks
    for the cell-to-cell connectivity first; the cell dofmap answers on both.

    Args:
        V: The function space.
        cells: Local cell indices.

    Returns:
        The local (block) dof indices, int32.
    """
    return np.unique(cell_dofs(V)[np.asarray(cells, dtype=np.int64)]).astype(np.int32)


def create_mesh(comm, cells: np.ndarray, x: np.ndarray, gdim: int, cell_name: str,
                interior_facets: bool = False):
    """Distribute a P1 simplex mesh given on one rank (collective).

    DOLFINx 0.5's ``create_mesh`` ghosts the cells across the ranks' shared facets
    (``GhostMode.shared_facet``) by default; 0.9's default partitioner ghosts none. Without
    ghosts an interior facet on a rank boundary has one cell on each rank and no rank
    integrates it (0.9 then assembles ``dS`` integrals that differ from serial, and a
    two-rank shell run was seen to hang), so a mesh with interior-facet integrals asks for
    the shared-facet ghosts on 0.9 too. Other meshes keep each release's default.

    Args:
        comm: The communicator to distribute over.
        cells: The simplices (other ranks pass an empty array).
        x: The vertex coordinates (other ranks pass an empty array).
        gdim: The geometric dimension.
        cell_name: ``"triangle"`` or ``"tetrahedron"``.
        interior_facets: The forms on the mesh integrate over interior facets (``dS``, a
            shell's hinges): ghost the cells across shared facets on every release.

    Returns:
        The distributed DOLFINx mesh.
    """
    if LEGACY:
        domain = ufl.Mesh(ufl.VectorElement(
            "Lagrange", ufl.Cell(cell_name, geometric_dimension=gdim), 1))
        return dmesh.create_mesh(comm, cells, x, domain)  # shared_facet ghosts by default
    domain = ufl.Mesh(basix.ufl.element("Lagrange", cell_name, 1, shape=(gdim,)))
    partitioner = None
    if interior_facets and comm.size > 1:
        partitioner = dmesh.create_cell_partitioner(dmesh.GhostMode.shared_facet)
    return dmesh.create_mesh(comm, cells, x, domain, partitioner=partitioner)


def colliding_cells(mesh, points: np.ndarray):
    """Local cells containing each of a set of points.

    Args:
        mesh: The DOLFINx mesh.
        points: The points, (n, 3).

    Returns:
        An adjacency list point -> local cells containing it.
    """
    if LEGACY:
        tree = geometry.BoundingBoxTree(mesh, mesh.topology.dim)
        candidates = geometry.compute_collisions(tree, points)
    else:
        tree = geometry.bb_tree(mesh, mesh.topology.dim)
        candidates = geometry.compute_collisions_points(tree, points)
    return geometry.compute_colliding_cells(mesh, candidates, points)


def expression(expr, points: np.ndarray, jit_options: dict | None = None) -> fem.Expression:
    """A compiled UFL expression at reference points (evaluate it with :func:`evaluate`).

    Args:
        expr: The UFL expression.
        points: Points on the reference cell, (n, tdim).
        jit_options: FFCx JIT options.
    """
    if LEGACY:
        return fem.Expression(expr, points, jit_params=jit_options)
    return fem.Expression(expr, points, jit_options=jit_options)


def evaluate(expr: fem.Expression, mesh, cells: np.ndarray) -> np.ndarray:
    """Values of a compiled expression on local cells.

    Args:
        expr: The compiled expression.
        mesh: The mesh it lives on.
        cells: Local cell indices.

    Returns:
        A (num_cells, points * value_size) array.
    """
    values = expr.eval(cells) if LEGACY else expr.eval(mesh, cells)
    return values.reshape(len(cells), -1)


def basix_cell(name: str):
    """basix's cell type of a cell name.

    Args:
        name: ``"interval"``, ``"triangle"`` or ``"tetrahedron"``.
    """
    import basix

    if LEGACY:
        return basix.cell.string_to_type(name)
    return basix.CellType[name]


def reference_quadrature(cell_name: str, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Points and weights of basix's default rule of ``degree`` on a reference cell.

    This is the rule FFCx uses for ``quadrature_degree`` with the default scheme.

    Args:
        cell_name: ``"interval"``, ``"triangle"`` or ``"tetrahedron"``.
        degree: The degree the rule integrates exactly.

    Returns:
        The points (n, tdim) and weights (n,).
    """
    import basix

    cell = basix_cell(cell_name)
    if LEGACY:
        return basix.make_quadrature(basix.quadrature.string_to_type("default"), cell, degree)
    return basix.make_quadrature(cell, degree)


def compile_forms_together(forms: dict[str, ufl.Form], jit_options: dict) -> dict:
    """Compile several real-valued forms on one mesh into one FFCx module (one gcc run).

    ``fem.form`` compiles every form into its own C module; the forms of one problem
    compiled together take about half the time with a cold cache. Under MPI rank 0 compiles
    and the others then load the module from the cache (DOLFINx's ``mpi_jit_decorator``).
    The Forms built are the ones ``fem.form`` builds (same coefficients, constants,
    subdomain data), so they go to the ``fem.petsc`` assemblers like any other.

    Args:
        forms: Name -> UFL form, all on one mesh.
        jit_options: FFCx JIT options (cache directory, compiler flags).

    Returns:
        Name -> compiled DOLFINx Form.
    """
    ufl_forms = list(forms.values())
    mesh = ufl_forms[0].ufl_domain().ufl_cargo()
    if LEGACY:
        p_ffcx = ffcx.get_parameters({"scalar_type": "double"})
        p_jit = jit.get_parameters(jit_options)

        @jit.mpi_jit_decorator
        def compile_all():
            return ffcx.codegeneration.jit.compile_forms(ufl_forms, parameters=p_ffcx, **p_jit)
    else:
        p_ffcx = ffcx.get_options({"scalar_type": np.float64})
        p_jit = jit.get_options(jit_options)

        @jit.mpi_jit_decorator
        def compile_all():
            return ffcx.codegeneration.jit.compile_forms(ufl_forms, options=p_ffcx, **p_jit)

    compiled, module, code = compile_all(mesh.comm)
    build = _legacy_form if LEGACY else _current_form
    return {name: build(form, ufcx_form, module, code, mesh)
            for name, form, ufcx_form in zip(forms, ufl_forms, compiled)}


def _coefficients(form: ufl.Form, ufcx_form, positions: str) -> list:
    original = form.coefficients()
    where = getattr(ufcx_form, positions)
    return [original[where[i]]._cpp_object for i in range(ufcx_form.num_coefficients)]


def _legacy_form(form: ufl.Form, ufcx_form, module, code, mesh):
    """A 0.5 ``fem.FormMetaClass`` Form from one ufcx form of a jointly compiled module."""
    subdomains, = form.subdomain_data().values()
    spaces = [arg.ufl_function_space()._cpp_object for arg in form.arguments()]
    coefficients = _coefficients(form, ufcx_form, "original_coefficient_position")
    constants = [c._cpp_object for c in form.constants()]
    types = _cpp.fem.IntegralType
    markers = {types.cell: subdomains.get("cell"),
               types.exterior_facet: subdomains.get("exterior_facet"),
               types.interior_facet: subdomains.get("interior_facet"),
               types.vertex: subdomains.get("vertex")}
    formcls = type("Form", (fem.FormMetaClass, _cpp.fem.Form_float64), {})
    return formcls(ufcx_form, spaces, coefficients, constants, markers, mesh, module.ffi, code)


def _current_form(form: ufl.Form, ufcx_form, module, code, mesh):
    """A 0.9 ``fem.Form`` from one ufcx form of a jointly compiled module.

    ``mesh`` is the UFL domain's cargo, which in 0.9 is the C++ mesh. The same steps as the
    nested ``_form`` of ``dolfinx.fem.form`` (0.9.0): subdomain ids per integral type, their
    integration entities, then the C++ form.
    """
    domain, = form.subdomain_data().keys()
    data = form.subdomain_data()[domain]
    spaces = [arg.ufl_function_space()._cpp_object for arg in form.arguments()]
    coefficients = _coefficients(form, ufcx_form, "original_coefficient_positions")
    constants = [c._cpp_object for c in form.constants()]
    ids: dict[str, list] = {kind: [] for kind in data}
    for integral in form.integrals():
        if integral.subdomain_data() is None:
            continue
        sid = integral.subdomain_id()
        if sid == "everywhere":
            continue
        ids[integral.integral_type()].extend(
            [s for s in sid if s != "everywhere"] if isinstance(sid, tuple) else [sid])
    to_dolfinx = _forms._ufl_to_dolfinx_domain
    subdomains = {to_dolfinx[kind]: _forms.get_integration_domains(
        to_dolfinx[kind], values[0], sorted(ids[kind])) for kind, values in data.items()}
    cpp_form = _forms.form_cpp_class(np.float64)(
        module.ffi.cast("uintptr_t", module.ffi.addressof(ufcx_form)), spaces, coefficients,
        constants, subdomains, {}, mesh)
    return fem.Form(cpp_form, ufcx_form, code, module)


#: Paths of the FFCx locks (``<cache>/<module>.c``) this process took; see
#: :func:`jit_locks_released`.
_OWN_JIT_LOCKS: set[str] = set()


def _lock_path(cache_dir, module_name: str) -> Path:
    return Path(cache_dir).expanduser().resolve().joinpath(module_name).with_suffix(".c")


#: Seconds a compile waits for another process compiling the same module (FFCx and DOLFINx
#: wait 10 s, then fail with "JIT compilation timed out"; a large module takes minutes:
#: docs/cloth.md, "DOLFINx 0.9"). Two runs started together on a cold cache, or two test
#: workers, compile the same module at once.
JIT_WAIT_S = 1800


def _get_cached_module_recording(module_name, object_names, cache_dir, timeout):
    """FFCx's ``get_cached_module`` that records the locks this process takes, first
    restores the lock of a module left ready without one, and waits :data:`JIT_WAIT_S`
    (at least ``timeout``) for another process compiling the module, saying so in one line
    on standard error.

    FFCx treats ``<module>.c`` as the lock and ``<module>.c.cached`` as "ready". A module
    with ``.c.cached`` but no ``.c`` (its lock renamed by someone else while it compiled) is
    poisoned for good: every later compile takes the free lock, compiles, then fails to create
    the existing ``.c.cached`` (``FileExistsError``) and renames the lock again. The module's
    library is complete (it is written before ``.c.cached``), so the lock is put back and
    FFCx loads it.

    A lock that did not exist before the call and exists after it raised (a signal landing
    after FFCx created it) is taken as this process's: another process creating the same lock
    in those microseconds is not ruled out, and would see its lock renamed as after a failure.
    """
    lock = _lock_path(cache_dir, module_name)
    if lock.with_suffix(".c.cached").exists() and not lock.exists():
        try:
            open(lock, "x").close()
        except OSError:
            pass
    existed = lock.exists()
    wait = max(int(timeout), JIT_WAIT_S)
    if existed and not lock.with_suffix(".c.cached").exists():
        print(f"fem-anim: waiting up to {wait} s for another process compiling {lock.name} "
              f"(if none is running, remove {lock})", file=sys.stderr, flush=True)
    try:
        obj, module = _FFCX_GET_CACHED_MODULE(module_name, object_names, cache_dir, wait)
    except BaseException:
        if not existed and lock.exists():
            _OWN_JIT_LOCKS.add(str(lock))
        raise
    if obj is None:
        _OWN_JIT_LOCKS.add(str(lock))
    return obj, module


_FFCX_GET_CACHED_MODULE = ffcx.codegeneration.jit.get_cached_module
# ``compile_forms``/``compile_expressions`` look the name up at each call, so every compile of
# this process (fem_anim's, DOLFINx's ``fem.form``, ``Expression``) goes through the recorder.
ffcx.codegeneration.jit.get_cached_module = _get_cached_module_recording


@contextmanager
def jit_locks_released(jit_options: dict | None = None):
    """Release the JIT-cache locks that a compile interrupted inside this block leaves.

    FFCx (0.5 and 0.9 alike) takes ``<module>.c`` in the cache as a lock and writes
    ``<module>.c.cached`` when the module is ready; on an Exception raised inside its compile
    it renames the lock to ``.c.failed``, but a KeyboardInterrupt, or any exception raised
    between its creating the lock (``get_cached_module``) and entering its ``try`` (a signal's
    :class:`~fem_anim.errors.Interrupted` landing there), leaves it, and every later compile
    of that module waits ``timeout`` seconds and fails ("JIT compilation timed out"). When
    the block ends with any exception, the locks made since it began that have no
    ``.c.cached`` and that this process took are renamed as FFCx does (one FFCx already
    renamed is gone). Locks of other processes are left alone, even if made since: one of
    them may be compiling still, and renaming its lock poisons its module (see
    :func:`_get_cached_module_recording`).

    Args:
        jit_options: FFCx JIT options (their ``cache_dir`` is searched).
    """
    options = jit.get_parameters(jit_options) if LEGACY else jit.get_options(jit_options)
    cache = Path(str(options["cache_dir"])).expanduser().resolve()
    since = time.time() - 1.0
    try:
        yield
    except BaseException:
        for lock in cache.glob("libffcx_*.c"):
            try:
                if str(lock) in _OWN_JIT_LOCKS and lock.stat().st_mtime >= since and \
                        not lock.with_suffix(".c.cached").exists():
                    os.replace(lock, lock.with_suffix(".c.failed"))
            except OSError:
                pass
        raise
