"""Shells: membrane and hinge-bending energies against the numpy reference and theory.

The energies of :mod:`fem_anim.problem.shell_terms` are compared with the hyper-dual
reference :mod:`fem_anim.reference.shell_energy` (energy, gradient, Hessian), with the
closed-form stress of a uniformly stretched membrane (patch test), with Kirchhoff-Love's
bending energy of a cylinder, and a clamped plate's tip deflection is fitted under refinement.
"""

from __future__ import annotations

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.forms.lame import lame_parameters
from fem_anim.forms.shell_bending import flexural_rigidity, hinge_stiffness
from fem_anim.meshes.sheet import structured_sheet
from fem_anim.problem.shell_terms import ShellEnergy, shell_measures
from fem_anim.reference import shell_energy as reference


MU, LMBDA, THICKNESS, K = 3.0, 2.0, 0.1, 0.7


def surface(points, cells, degree=1):
    """The DOLFINx surface mesh, its P1 vector space and ``order[dolfinx dof] = reference
    dof`` (serial)."""
    mesh = compat.create_mesh(MPI.COMM_SELF, np.asarray(cells, np.int64), points, 3,
                              "triangle")
    V = compat.vector_space(mesh, degree)
    coords = V.tabulate_dof_coordinates()
    node = np.argmin(np.linalg.norm(coords[:, None] - points[None], axis=2), axis=1)
    return mesh, V, (node[:, None] * 3 + np.arange(3)).ravel()


#: JIT options of the forms the shell tests compile themselves (:func:`assemble`,
#: :func:`clamped_newton`). gcc's ``-O1`` does the same IEEE arithmetic as DOLFINx's default
#: ``-O2`` (no fast-math) and compiles the large kernels (Kirchhoff-Love's P2 edge terms: MBs
#: of C) several times faster: most of a cold JIT cache's time in tests/test_shell_kl.py
#: (docs/getting_started.md, the cold CI timing). The package's own kernels keep
#: ``JIT_OPTIONS``.
TEST_JIT = {"cffi_extra_compile_args": ["-O1", "-g0"]}


def energy_forms(form, u) -> dict:
    """``form``, its gradient and its Hessian in ``u``, compiled together into one module
    (:func:`fem_anim.compat.compile_forms_together`, :data:`TEST_JIT`)."""
    return compat.compile_forms_together(
        {"E": form, "g": ufl.derivative(form, u),
         "H": ufl.derivative(ufl.derivative(form, u), u)}, TEST_JIT)


def assemble(form, u):
    """Energy, gradient and dense Hessian of ``form`` in ``u`` (DOLFINx dof order)."""
    forms = energy_forms(form, u)
    E = fem.assemble_scalar(forms["E"])
    g = fem_petsc.assemble_vector(forms["g"]).array.copy()
    H = fem_petsc.assemble_matrix(forms["H"])
    H.assemble()
    dense = H.convert("dense")  # petsc4py 3.22's array is a view: copied while it lives
    return E, g, dense.getDenseArray().copy()


@pytest.mark.parametrize("model", ["stvk", "neohookean"])
def test_energy_gradient_hessian_equal_the_reference(model):
    """Membrane + hinge energy, gradient and Hessian = the hyper-dual reference to ~1e-13,
    on a rest surface that is not flat (rest angles) with a large random displacement; the
    DOLFINx mesh has every other triangle reversed (the reference orients by topology)."""
    rng = np.random.default_rng(1)
    points, cells = structured_sheet([1.0, 1.0], [2, 2], triangulation="alternate")
    points = points + 0.05 * rng.standard_normal(points.shape)
    flipped = cells.copy()  # DOLFINx gets every other triangle oppositely oriented
    flipped[::2] = flipped[::2, ::-1]
    mesh, V, order = surface(points, flipped)
    u = fem.Function(V)
    displacement = 0.2 * rng.standard_normal(points.shape)
    u.x.array[:] = displacement.ravel()[order]
    x = (points + displacement).ravel()
    dx, dS = shell_measures(mesh)
    E, g, H = assemble(ShellEnergy(model, MU, LMBDA, THICKNESS, fem.Constant(
        mesh, PETSc.ScalarType(K))).energy(u, dx, dS), u)
    args = (points, cells, model, MU, LMBDA, THICKNESS, K, x)
    E_ref = reference.shell_energy(*args)
    g_ref = reference.shell_gradient(*args)[order]
    H_ref = reference.shell_hessian(*args).toarray()[np.ix_(order, order)]
    assert abs(E - E_ref) <= 1e-12 * abs(E_ref)
    assert np.abs(g - g_ref).max() <= 1e-12 * np.abs(g_ref).max()
    assert np.abs(H - H_ref).max() <= 1e-12 * np.abs(H_ref).max()
    # the bending part is there and is not negligible
    assert reference.shell_energy(*args[:6], 0.0, x) < 0.5 * E_ref


def _second_piola(model, C, mu, lmbda):
    """S of the plane-stress membrane laws (2x2), closed form."""
    ls = 2 * mu * lmbda / (lmbda + 2 * mu)
    I = np.eye(2)
    if model == "stvk":
        E = (C - I) / 2
        return 2 * mu * E + ls * np.trace(E) * I
    Ci = np.linalg.inv(C)
    return mu * (I - Ci) + ls * np.log(np.linalg.det(C)) / 2 * Ci


@pytest.mark.parametrize("model", ["stvk", "neohookean"])
def test_patch_uniform_stretch_gives_the_analytic_stress_and_energy(model):
    """A sheet in a tilted plane stretched by (1.3, 0.8) in its plane: energy t A psi and the
    force on its edge x = a, t b (F S) e_1, both from the closed-form plane-stress laws."""
    a, b, stretch = 2.0, 1.0, np.diag([1.3, 0.8])
    flat_points, cells = structured_sheet([a, b], [3, 2], triangulation="alternate")
    R = np.linalg.qr(np.array([[1.0, 0.3, 0.2], [0.1, 1.0, -0.4], [0.5, 0.2, 1.0]]))[0]
    points = flat_points @ R.T
    mesh, V, order = surface(points, cells)
    u = fem.Function(V)
    stretched = flat_points.copy()
    stretched[:, :2] = flat_points[:, :2] @ stretch.T
    u.x.array[:] = (stretched @ R.T - points).ravel()[order]
    dx, _ = shell_measures(mesh)
    E, g, _ = assemble(ShellEnergy(model, MU, LMBDA, THICKNESS, 0).energy(u, dx, None), u)
    C = stretch.T @ stretch
    S = _second_piola(model, C, MU, LMBDA)
    if model == "stvk":
        G = (C - np.eye(2)) / 2
        psi = MU * np.sum(G * G) + MU * LMBDA / (LMBDA + 2 * MU) * np.trace(G) ** 2
    else:
        lnJ = np.log(np.linalg.det(C)) / 2
        psi = MU / 2 * (np.trace(C) - 2) - MU * lnJ + MU * LMBDA / (LMBDA + 2 * MU) * lnJ**2
    assert E == pytest.approx(THICKNESS * a * b * psi, rel=1e-12)
    coords = V.tabulate_dof_coordinates() @ R  # back in the sheet's plane
    edge = np.isclose(coords[:, 0], a)
    force = g.reshape(-1, 3)[edge].sum(axis=0)
    P = R[:, :2] @ stretch @ S  # first Piola (3x2) in world axes
    assert np.allclose(force, THICKNESS * b * P[:, 0], rtol=1e-11, atol=1e-12)


def test_cylinder_bending_energy_is_kirchhoff_love():
    """A sheet rolled onto a cylinder of radius R (vertices on the circle, exact arcs):
    bending energy D/2 kappa^2 per hinged area, exactly, for every triangulation of
    squares into two triangles, whichever axis the cylinder has; half the triangles are
    given to DOLFINx reversed (a flat rest state: the orientation fix keeps theta = 0)."""
    E_mod, nu, t, R, n = 2e6, 0.3, 0.01, 0.7, 4
    D = flexural_rigidity(E_mod, nu, t)
    for triangulation in ("right", "left", "alternate"):
        points, cells = structured_sheet([1.0, 1.0], [n, n], triangulation=triangulation)
        cells[1::2] = cells[1::2, ::-1]  # neighbours oppositely oriented: flat rest, theta 0
        mesh, V, order = surface(points, cells)
        u = fem.Function(V)
        _, dS = shell_measures(mesh)
        form = ShellEnergy("stvk", 1.0, 1.0, t, fem.Constant(
            mesh, PETSc.ScalarType(hinge_stiffness(E_mod, nu, t)))).bending_energy(u, dS)
        for axis in (0, 1):
            rolled = points.copy()
            s = points[:, axis]
            rolled[:, axis], rolled[:, 2] = R * np.sin(s / R), R * (1 - np.cos(s / R))
            u.x.array[:] = (rolled - points).ravel()[order]
            hinged_area = (n - 1) / n  # interior edges across the bending direction
            expected = D / 2 / R**2 * hinged_area
            assert fem.assemble_scalar(fem.form(form)) == pytest.approx(expected, rel=1e-10)


def clamped_newton(energy, u: fem.Function, clamped):
    """Newton's method on ``energy`` (a UFL form of ``u``) in serial, with u = 0 held on the
    dofs at the points where ``clamped(x)`` holds. Returns ``solve(iterations, tol,
    must_converge=True)``, which updates ``u`` until the update is below ``tol`` of the
    largest displacement (raising after ``iterations`` if ``must_converge``); the forms are
    compiled once (:func:`energy_forms`), so a load can change between calls through its
    Constants."""
    V = u.function_space
    forms = energy_forms(energy, u)
    residual, tangent = forms["g"], forms["H"]
    held = fem.locate_dofs_geometrical(V, clamped)
    bc = fem.dirichletbc(np.zeros(3), held, V)
    held_dofs = (held[:, None] * 3 + np.arange(3)).ravel()
    du = fem.Function(V)
    ksp = PETSc.KSP().create(MPI.COMM_SELF)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")

    def solve(iterations: int, tol: float, must_converge: bool = True) -> None:
        for _ in range(iterations):
            A = fem_petsc.assemble_matrix(tangent, bcs=[bc])
            A.assemble()
            b = fem_petsc.assemble_vector(residual)
            b.array[held_dofs] = 0.0  # the clamp holds u = 0: no residual there
            b.scale(-1.0)
            ksp.setOperators(A)
            ksp.solve(b, compat.petsc_vec(du))
            u.x.array[:] += du.x.array
            if np.abs(du.x.array).max() < tol * np.abs(u.x.array).max():
                return
        if must_converge:
            raise AssertionError("Newton did not converge")

    return solve


def _cantilever_tip(n: int, triangulation: str = "right") -> float:
    """Tip deflection / Kirchhoff-Love's q L^4 / (8 D) of a plate (L = 1, width 1/4) clamped
    at x = 0 under its own weight, ``n`` squares along its length.

    The clamp holds the vertices at x = 0 and one column of squares behind it (x = -h), so
    the hinge at x = 0 fixes the slope; the deflection is small (q L^4 / (8 D) = 1.3e-2 L).
    Newton on membrane + bending + gravity from the rest state."""
    L, W, t, E_mod, nu, rho, g = 1.0, 0.25, 0.01, 1e10, 0.3, 1000.0, 9.81
    h = L / n
    points, cells = structured_sheet([L + h, W], [n + 1, max(1, round(W / h))], [-h, 0, 0],
                                     triangulation)
    mesh, V, _ = surface(points, cells)
    u = fem.Function(V)
    mu, lmbda = lame_parameters(E_mod, nu)
    dx, dS = shell_measures(mesh)
    shell = ShellEnergy("stvk", mu, lmbda, t, fem.Constant(
        mesh, PETSc.ScalarType(hinge_stiffness(E_mod, nu, t))))
    gravity = fem.Constant(mesh, np.array([0.0, 0.0, -g]))
    energy = shell.energy(u, dx, dS) - rho * t * ufl.inner(gravity, u) * dx
    clamped_newton(energy, u, lambda x: x[0] <= 1e-12)(10, 1e-12, must_converge=False)
    tip = np.isclose(V.tabulate_dof_coordinates()[:, 0], L)
    w_kl = rho * t * g * L**4 / (8 * flexural_rigidity(E_mod, nu, t))
    return -u.x.array.reshape(-1, 3)[tip, 2].mean() / w_kl


def test_cantilever_plate_converges_at_first_order():
    """The clamped plate's tip deflection converges at order 1 (fitted from n = 4, 8, 16),
    to a limit within 25 % above Kirchhoff-Love's: the hinge energy of a right-triangle mesh
    couples bending and twist (docs/cloth.md), so its plate is softer than Kirchhoff-Love's
    although a cylinder's energy is exact (the test above)."""
    w1, w2, w3 = (_cantilever_tip(n) for n in (4, 8, 16))
    order = np.log2((w1 - w2) / (w2 - w3))
    limit = (w2**2 - w1 * w3) / (2 * w2 - w1 - w3)
    assert 0.8 < order < 1.3
    assert 1.0 < limit < 1.25


# -- shell scenes: the whole run -----------------------------------------------------------

SHEET = """
name = "sheet"
[mesh]
shape = "sheet"
size = [0.4, 0.2]
origin = [0.0, 0.0, 0.0]
element_size = 0.1
[shell]
thickness = 0.002
[material]
model = "stvk"
youngs_modulus = 1.0e6
poisson_ratio = 0.3
density = 500.0
[time]
dt = 0.02
steps = 12
[gravity]
acceleration = [0.0, 0.0, -9.81]
[[pin]]
min = [-0.01, -0.01, -0.01]
max = [0.01, 0.21, 0.01]
[output]
render = false
"""


def _run(tmp_path, name, text, *args):
    """Run a scene in this process; (exit code, stderr lines)."""
    import contextlib
    import io

    from fem_anim.cli import main as cli_main

    scene = tmp_path / f"{name}.toml"
    scene.write_text(text)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli_main(["run", str(scene), "-o", str(tmp_path / name), "--quiet", *args])
    return code, [line for line in err.getvalue().splitlines() if line.strip()]


def test_swinging_sheet_keeps_its_energy_with_newmark(tmp_path):
    """A sheet hinged along x = 0 swings down under gravity (0.24 s). Undamped Newmark's
    energy drift is small and falls at second order as dt halves; implicit Euler's is
    larger and falls at first order."""
    import json

    drifts = {}
    for integrator in ("newmark", "implicit_euler"):
        for dt, steps in ((0.02, 12), (0.01, 24)):
            name = f"{integrator}_{steps}"
            code, err = _run(tmp_path, name, SHEET, "--set", f"time.integrator={integrator}",
                             "--set", f"time.dt={dt}", "--set", f"time.steps={steps}")
            assert code == 0, err
            energy = json.loads((tmp_path / name / "summary.json").read_text())["energy"]
            assert energy["exchanged_energy"] > 1e-3
            drifts[integrator, steps] = energy["drift"]
    newmark = np.log2(drifts["newmark", 12] / drifts["newmark", 24])
    euler = np.log2(drifts["implicit_euler", 12] / drifts["implicit_euler", 24])
    assert abs(drifts["newmark", 24]) < 0.01
    assert newmark > 1.7 and 0.7 < euler < 1.3
    assert abs(drifts["implicit_euler", 24]) > 5 * abs(drifts["newmark", 24])


def test_area_density_is_density_times_thickness(tmp_path):
    """The assembled mass of a shell scene is rho t A (kg), the sheet's area A = 0.08 m^2."""
    from fem_anim.mesh.bodies import build_scene_mesh
    from fem_anim.problem.objective import EnergyProblem
    from fem_anim.scene import load_scene

    path = tmp_path / "sheet.toml"
    path.write_text(SHEET)
    scene = load_scene(path)
    problem = EnergyProblem(scene, build_scene_mesh(MPI.COMM_SELF, scene))
    M = fem_petsc.assemble_matrix(problem.mass_form)
    M.assemble()
    ones = M.createVecRight()
    ones.set(1.0)
    Mx = M.createVecLeft()
    M.mult(ones, Mx)
    # 1^T M 1 = 3 m_total over the three displacement components
    assert Mx.sum() / 3 == pytest.approx(500.0 * 0.002 * 0.4 * 0.2, rel=1e-12)


def two_ranks_equal_serial(text: str, steps: int, tmp_path):
    """Run the scene ``text`` (``steps`` steps) on 1 and 2 ranks: every step's kinetic,
    elastic and gravity energies and the final displacement equal to 1e-8. Returns the two
    final frames (meshio, serial first) for further checks."""
    import meshio

    from conftest import run_on_one_and_more_ranks
    from test_cli import read_stats

    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    outs = run_on_one_and_more_ranks(scene, tmp_path)
    a, b = read_stats(outs[1] / "stats.csv"), read_stats(outs[2] / "stats.csv")
    assert len(a) == len(b) == steps
    for ra, rb in zip(a, b):
        for key in ("kinetic", "elastic", "gravity"):
            assert rb[key] == pytest.approx(ra[key], rel=1e-8, abs=1e-14), (ra["step"], key)
    ua = meshio.read(outs[1] / "final.vtu")
    ub = meshio.read(outs[2] / "final.vtu")
    du = ub.point_data["displacement"] - ua.point_data["displacement"]
    assert np.linalg.norm(du) <= 1e-8 * np.linalg.norm(ua.point_data["displacement"])
    return ua, ub


@pytest.mark.mpi
def test_two_ranks_equal_serial(tmp_path):
    """The swinging sheet on 2 ranks: stats energies and final displacement equal the
    serial run's to 1e-8 (hinges on edges between the ranks' cells included)."""
    ua, ub = two_ranks_equal_serial(SHEET, 12, tmp_path)
    ea = ua.cell_data["energy_density"][0]
    eb = ub.cell_data["energy_density"][0]
    assert np.abs(eb - ea).max() <= 1e-8 * np.abs(ea).max()


NON_MANIFOLD_OBJ = """v 0 0 0
v 1 0 0
v 0 1 0
v 0 -1 0
v 0 0 1
f 1 2 3
f 2 1 4
f 1 2 5
"""

BAD_SHELLS = {
    "zero thickness": ("", "thickness = 0.002", "thickness = 0.0", "shell.thickness"),
    "negative thickness": ("", "thickness = 0.002", "thickness = -0.001", "shell.thickness"),
    "2D scene": ("", "[mesh]\n", "[mesh]\ndim = 2\n", "mesh.dim = 3"),
    "P2": ("[element]\ndegree = 2\n", "", "", "element.degree = 1 only"),
    "contact without self": ("[contact]\nself = false\n", "", "", "contact.self = true"),
    "obstacle, consistent mass": ("[[obstacle]]\ntype = \"plane\"\nnormal = [0.0, 0.0, 1.0]"
                                  "\npoint = [0.0, 0.0, -1.0]\n", "", "",
                                  "material.mass = \"lumped\""),
    "sheet without [shell]": ("", "[shell]\nthickness = 0.002\n", "", "add a [shell] table"),
    "solid model": ("", "model = \"stvk\"", "model = \"corotated\"", "no membrane form"),
    "negative bending": ("", "thickness = 0.002", "thickness = 0.002\nbending = -1.0",
                         "shell.bending"),
    "non-manifold file": ("", "shape = \"sheet\"", "shape = \"file\"\nfile = \"fan.obj\"",
                          "non-manifold"),
}


@pytest.mark.parametrize("case", sorted(BAD_SHELLS))
def test_bad_shell_input_is_one_line_exit_2(case, tmp_path):
    """Each bad shell scene ends with exit code 2 and one ``fem-anim: error:`` line naming
    the problem."""
    extra, old, new, words = BAD_SHELLS[case]
    (tmp_path / "fan.obj").write_text(NON_MANIFOLD_OBJ)
    text = SHEET.replace(old, new, 1) if old else SHEET
    if case == "non-manifold file":
        text = text.replace("size = [0.4, 0.2]\n", "")
    code, err = _run(tmp_path, "bad", text + extra)
    assert code == 2
    assert len(err) == 1 and err[0].startswith("fem-anim: error: "), err
    assert words in err[0], err[0]


@pytest.mark.parametrize("triangulation", ["right", "left", "alternate"])
def test_gmsh_sheet_is_the_structured_sheet(triangulation):
    """gmsh's transfinite sheet (what scenes use) has the numpy sheet's triangles: the same
    vertex triples by coordinates (the bending energy depends on the triangulation)."""
    from fem_anim.mesh.gmsh_session import gmsh_arrays, gmsh_session
    from fem_anim.meshes import BUILDERS

    cfg = {"size": [0.6, 0.4], "element_size": 0.2, "origin": [1.0, 2.0, 0.0],
           "triangulation": triangulation}
    with gmsh_session("sheet", "") as model:
        points, cells, markers, names = gmsh_arrays(BUILDERS["sheet"](model, cfg), 2)
    reference_points, reference_cells = structured_sheet([0.6, 0.4], [3, 2], [1.0, 2.0, 0.0],
                                                         triangulation)

    def triples(p, c):
        return sorted(tuple(sorted(map(tuple, np.round(p[t, :2], 9)))) for t in c)

    assert triples(points, cells) == triples(reference_points, reference_cells)
    assert names.get("body") == 1


@pytest.mark.parametrize("model", ["stvk", "neohookean"])
def test_tube_is_stress_free_at_rest_and_hoop_stretch_is_analytic(model):
    """A tube (curved at rest: every hinge has a rest angle; the seam merged) has zero energy
    and force at rest; scaled radially by s its hinge angles do not change (zero bending)
    and each triangle is stretched by (1, s): energy t A psi(diag(1, s)) exactly."""
    from fem_anim.meshes.sheet import structured_tube

    radius, length, s = 0.3, 0.5, 1.2
    points, cells = structured_tube(radius, length, [3, 8], "alternate")
    assert len(points) == 4 * 8 and cells.max() == len(points) - 1
    mesh, V, order = surface(points, cells)
    u = fem.Function(V)
    dx, dS = shell_measures(mesh)
    shell = ShellEnergy(model, MU, LMBDA, THICKNESS, fem.Constant(mesh, PETSc.ScalarType(K)))
    E, g, _ = assemble(shell.energy(u, dx, dS), u)
    assert abs(E) < 1e-14 and np.abs(g).max() < 1e-12
    scaled = points * np.array([1.0, s, s])
    u.x.array[:] = (scaled - points).ravel()[order]
    assert abs(fem.assemble_scalar(fem.form(shell.bending_energy(u, dS)))) < 1e-14
    area = length * 8 * 2 * radius * np.sin(np.pi / 8)  # the polygonal tube's area
    C = np.diag([1.0, s * s])
    if model == "stvk":
        G = (C - np.eye(2)) / 2
        psi = MU * np.sum(G * G) + MU * LMBDA / (LMBDA + 2 * MU) * np.trace(G) ** 2
    else:
        lnJ = np.log(s)
        psi = MU / 2 * (1 + s * s - 2) - MU * lnJ + MU * LMBDA / (LMBDA + 2 * MU) * lnJ**2
    E = fem.assemble_scalar(fem.form(shell.membrane(u, dx)))
    assert E == pytest.approx(THICKNESS * area * psi, rel=1e-12)


def test_surface_file_runs_like_the_sheet(tmp_path):
    """The sheet written as an OBJ surface and read with mesh.shape = "file" gives the
    sheet's run (same triangles, same final displacement to rounding); two corners held,
    one of them a handle moving up."""
    import meshio

    from fem_anim.mesh.gmsh_session import gmsh_arrays, gmsh_session
    from fem_anim.meshes import BUILDERS

    cfg = {"size": [0.4, 0.2], "element_size": 0.1, "origin": [0.0, 0.0, 0.0],
           "triangulation": "right"}
    with gmsh_session("sheet", "") as model:
        points, cells, _, _ = gmsh_arrays(BUILDERS["sheet"](model, cfg), 2)
    points = np.column_stack([points, np.zeros(len(points))])
    meshio.write(tmp_path / "cloth.obj", meshio.Mesh(points, [("triangle", cells)]))
    corners = SHEET.replace(
        "[[pin]]\nmin = [-0.01, -0.01, -0.01]\nmax = [0.01, 0.21, 0.01]\n",
        "[[pin]]\nmin = [-0.01, -0.01, -0.01]\nmax = [0.01, 0.01, 0.01]\n"
        "[[pin]]\nmin = [-0.01, 0.19, -0.01]\nmax = [0.01, 0.21, 0.01]\n"
        "velocity = [0.0, 0.0, 0.5]\n").replace("steps = 12", "steps = 4")
    from_file = corners.replace('shape = "sheet"', 'shape = "file"\nfile = "cloth.obj"')
    results = {}
    for name, text in (("sheet", corners), ("file", from_file)):
        code, err = _run(tmp_path, name, text)
        assert code == 0, err
        final = meshio.read(tmp_path / name / "final.vtu")
        order = np.lexsort(final.points.T[::-1])
        results[name] = final.point_data["displacement"][order]
    assert np.abs(results["file"] - results["sheet"]).max() <= 1e-10
    # the handle moved its corner up by 0.5 m/s * 0.08 s
    assert results["sheet"][:, 2].max() == pytest.approx(0.04, rel=1e-9)
