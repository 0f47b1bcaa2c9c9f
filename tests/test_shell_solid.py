"""A shell and a soft solid in one step (issue 30): the joint objective and joint stepping.

:class:`fem_anim.problem.joint_objective.JointProblem` minimises g_s(x_s) + g_c(x_c) +
w kappa B(x_s, x_c) over both unknowns at once (docs/notes/shell_solid_coupling.md). Checked:

* the joint energy, gradient and Hessian equal the parts' (each an EnergyProblem, itself
  checked against the numpy reference in tests/test_reference*.py and tests/test_shell.py)
  plus the IPC barrier evaluated by ipctk on a union surface built here independently (the
  solid's boundary triangles from its cells, the shell's cells, thickness t as d_min), to
  1e-10; the joint gradient and Hessian pass a Taylor test (second-order remainders);
* a cloth square falling on a soft neo-Hookean cube pinned at its base: every step is
  intersection free by the independent check on the sheet and the cube's boundary
  triangles together, the sheet comes to lie on the cube (pairs form, its middle stays
  t above the top face), and the total energy never grows;
* a free cloth thrown at a free cube (no gravity, no ground): the total momentum of both
  bodies is kept to round-off;
* bad combinations are refused with one line each.
"""

from __future__ import annotations

import ipctk
import numpy as np
import pytest
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.contact.intersection import boundary_triangles, intersecting
from fem_anim.errors import SceneError
from fem_anim.scene import Scene
from fem_anim.simulation.joint_loop import JointSimulation

T = 1.0e-3  # m: the cloth's thickness (the barrier's d_min)
DHAT = 1.0e-3  # m
TOP = 0.1  # m: the cube's top face


def _solid(**extra) -> dict:
    scene = {"name": "cube",
             "mesh": {"shape": "box", "size": [0.1, 0.1, TOP], "origin": [-0.05, -0.05, 0.0],
                      "element_size": 0.05},
             "material": {"model": "neohookean", "youngs_modulus": 2.0e4,
                          "poisson_ratio": 0.3, "density": 500.0},
             "time": {"dt": 0.01, "steps": 10, "integrator": "implicit_euler"},
             "gravity": {"acceleration": [0.0, 0.0, -9.81]},
             "pin": [{"min": [-1.0, -1.0, -1e-6], "max": [1.0, 1.0, 1e-6]}]}
    scene.update(extra)
    return {k: v for k, v in scene.items() if v is not None}


def _shell(z: float = TOP + 0.003, **extra) -> dict:
    scene = {"name": "cloth",
             "mesh": {"shape": "sheet", "size": [0.16, 0.16], "origin": [-0.08, -0.08, z],
                      "element_size": 0.04},
             "shell": {"thickness": T},
             "material": {"model": "stvk", "youngs_modulus": 1.0e5, "poisson_ratio": 0.3,
                          "density": 300.0},
             "time": {"dt": 0.01, "steps": 10, "integrator": "implicit_euler"},
             "gravity": {"acceleration": [0.0, 0.0, -9.81]},
             "contact": {"dhat": DHAT}}
    scene.update(extra)
    return {k: v for k, v in scene.items() if v is not None}


def _simulation(solid: dict, shell: dict) -> JointSimulation:
    return JointSimulation(Scene.from_dict(solid), Scene.from_dict(shell))


def _union_surface(sim: JointSimulation):
    """Rest positions, triangles and the joint dof block of each vertex of the solid's
    boundary and the shell, built from the cells alone (serial)."""
    points, triangles, blocks, first = [], [], [], 0
    for k, part in enumerate(sim.parts):
        V = part.V
        cells = compat.cell_dofs(V)  # P1: one dof block per vertex
        X = V.tabulate_dof_coordinates()
        tris = boundary_triangles(cells) if cells.shape[1] == 4 else cells
        points.append(X)
        triangles.append(tris + first)
        blocks.append(sim.problem.layout.offsets[k] // 3 + np.arange(len(X)))
        first += len(X)
    return np.concatenate(points), np.concatenate(triangles), np.concatenate(blocks)


def _pinned(part) -> np.ndarray:
    """A part's pinned local dofs (unblocked)."""
    return np.concatenate([bc.dof_indices()[0] for bc in part.displacement_bcs]
                          + [np.empty(0, np.int32)])


def _dense(A: PETSc.Mat) -> np.ndarray:
    """A copy of the matrix as a dense array (taken while the converted matrix lives:
    petsc4py 3.22's ``getDenseArray`` is a view of its storage)."""
    D = A.convert("dense")
    out = D.getDenseArray().copy()
    D.destroy()
    return out


def _joint_state(sim: JointSimulation, seed: int = 0) -> PETSc.Vec:
    """The sheet lowered 1.6 mm onto the cube (pairs active: mid-surface 1.4 mm from the top,
    within t + d_hat), both bodies randomly deformed by up to 0.1 mm; pins kept."""
    rng = np.random.default_rng(seed)
    us = []
    for k, part in enumerate(sim.parts):
        u = 1e-4 * rng.uniform(-1, 1, part.u.x.array.size)
        if k == 1:
            u.reshape(-1, 3)[:, 2] -= 1.6e-3
        us.append(u)
    x = sim.problem.create_vector()
    sim.problem.load_guess(us, x)
    return x


@pytest.fixture(scope="module")
def staged():
    """The joint problem staged for one implicit-Euler step from rest (fixed kappa)."""
    sim = _simulation(_solid(), _shell(contact={"dhat": DHAT, "stiffness": 1.0e3}))
    zeros = [np.zeros(p.u.x.array.size) for p in sim.parts]
    sim.problem.stage(zeros, zeros, 1.0e-4, 0.01, 0.01, [None, None])
    return sim


def test_joint_objective_is_the_parts_plus_the_barrier(staged):
    """g, grad g and Hess g of the joint problem = the parts' + w kappa B of ipctk on the
    union surface built independently (exact barrier Hessian), to 1e-10."""
    sim, p = staged, staged.problem
    x = _joint_state(sim)
    w, kappa = float(p.weight.value), p.ipc.kappa
    points, tris, blocks = _union_surface(sim)
    mesh = ipctk.CollisionMesh(points, ipctk.edges(tris), tris)
    p.set_state(x)
    u = np.concatenate([part.u.x.array.reshape(-1, 3) for part in sim.parts])
    xs = points + u
    collisions = ipctk.NormalCollisions()
    collisions.use_area_weighting = True
    collisions.build(mesh, xs, DHAT, T)
    assert len(collisions) > 0
    barrier = ipctk.BarrierPotential(DHAT, 1.0, True)
    parts_x = [part.create_vector() for part in sim.parts]
    p.split(x, parts_x)
    # energy
    g_parts = sum(part.objective(None, xp) for part, xp in zip(sim.parts, parts_x))
    B = barrier(collisions, mesh, xs)
    assert B > 0
    expected = g_parts + w * kappa * B
    assert abs(p.objective(None, x) - expected) <= 1e-10 * abs(expected)
    # gradient (pinned rows: x - u_bc, from the parts)
    order = (blocks[:, None] * 3 + np.arange(3)).ravel()
    grad = np.zeros(x.getSize())
    grad[order] = w * kappa * barrier.gradient(collisions, mesh, xs)
    pinned = np.zeros(x.getSize(), bool)
    for k, part in enumerate(sim.parts):
        pinned[p.layout.offsets[k] + _pinned(part)] = True
    grad[pinned] = 0.0
    for part, xp in zip(sim.parts, parts_x):
        b = part.create_vector()
        part.residual(None, xp, b)
        grad[p.layout.local_slice(sim.parts.index(part))] += b.array
    b = p.create_vector()
    p.residual(None, x, b)
    assert np.abs(b.array - grad).max() <= 1e-10 * np.abs(grad).max()
    # Hessian, the barrier's exact
    p.ipc.exact_hessian(True)
    try:
        A = p.create_matrix()
        p.jacobian(None, x, A, A)
        H = np.zeros((x.getSize(), x.getSize()))
        Hb = barrier.hessian(collisions, mesh, xs, ipctk.PSDProjectionMethod.NONE).toarray()
        H[np.ix_(order, order)] = w * kappa * Hb
        H[pinned, :] = 0.0
        H[:, pinned] = 0.0
        for k, (part, xp) in enumerate(zip(sim.parts, parts_x)):
            Ap = part.create_matrix()
            part.jacobian(None, xp, Ap, Ap)
            s = p.layout.local_slice(k)
            H[s, s] += _dense(Ap)
        assert np.abs(_dense(A) - H).max() <= 1e-10 * np.abs(H).max()
    finally:
        p.ipc.exact_hessian(False)


def test_joint_gradient_and_hessian_pass_a_taylor_test(staged):
    """Along a random free direction d: g(x + e d) - g(x) - e r.d and r(x + e d) - r(x) -
    e H d fall as e^2 (ratios near 4 per halving of e), with pairs of both bodies active."""
    sim, p = staged, staged.problem
    x = _joint_state(sim, seed=1)
    rng = np.random.default_rng(2)
    d = x.duplicate()
    d.array[:] = 2e-5 * rng.uniform(-1, 1, d.array.size)
    b = p.create_vector()
    p.residual(None, x, b)
    free = b.duplicate()
    free.array[:] = 1.0
    for k, part in enumerate(sim.parts):
        rows = _pinned(part)
        rows = rows[rows < 3 * p.layout.owned[k]]
        free.array[p.layout.offsets[k] + rows] = 0.0
    d.pointwiseMult(d, free)
    p.set_state(x)
    assert p.ipc.num_pairs > 0
    p.ipc.exact_hessian(True)
    try:
        A = p.create_matrix()
        p.jacobian(None, x, A, A)
        Hd = d.duplicate()
        A.mult(d, Hd)
        g0, slope = p.objective(None, x), b.dot(d)
        energy_rem, grad_rem = [], []
        for e in (1.0, 0.5, 0.25, 0.125):
            xe = x.copy()
            xe.axpy(e, d)
            energy_rem.append(abs(p.objective(None, xe) - g0 - e * slope))
            be = p.create_vector()
            p.residual(None, xe, be)
            be.axpy(-1.0, b)
            be.axpy(-e, Hd)
            be.pointwiseMult(be, free)
            grad_rem.append(be.norm())
    finally:
        p.ipc.exact_hessian(False)
    for rem in (energy_rem, grad_rem):
        ratios = np.array(rem[:-1]) / np.array(rem[1:])
        assert np.all((ratios > 3.5) & (ratios < 4.5)), ratios


def _vertex_positions(sim: JointSimulation, states) -> np.ndarray:
    return np.concatenate([part.V.tabulate_dof_coordinates() + s.u.reshape(-1, 3)
                           for part, s in zip(sim.parts, states)])


def _body_distance(mesh, x: np.ndarray) -> float:
    """The smallest distance between the two bodies' surfaces (m), by ipctk's pairs
    within 1 cm between the mesh's connected components (the cube's boundary, the sheet)."""
    collisions = ipctk.NormalCollisions()
    collisions.build(mesh, x, 0.01)
    return float(np.sqrt(collisions.compute_minimum_distance(mesh, x)))


def test_cloth_falls_on_a_soft_cube_without_intersection():
    """The cloth falls 3 mm onto the cube pinned at its base (8 steps of 10 ms): no step
    has a crossing of the sheet and the cube's boundary nor a sheet vertex inside the cube
    (the independent check), the sheet's mid-surface never comes nearer the cube than t and
    ends resting on it (within t + d_hat), its edges hang below the top face, and the total
    energy never grows."""
    sim = _simulation(_solid(), _shell())
    points, tris, _ = _union_surface(sim)
    mesh = ipctk.CollisionMesh(points, ipctk.edges(tris), tris)
    mesh.can_collide = ipctk.make_connected_components_filter(tris)
    states = sim.initial_state()
    energies = [sim.energies(states)["total_energy"]]
    distances = []
    for _ in range(8):
        states, _ = sim.step(states, 0.01)
        x = _vertex_positions(sim, states)
        assert not intersecting(x, tris)
        distances.append(_body_distance(mesh, x))
        energies.append(sim.energies(states)["total_energy"])
    assert min(distances) > T
    assert distances[-1] < T + DHAT
    assert sim.problem.ipc.num_pairs > 0
    cloth = sim.parts[1].V.tabulate_dof_coordinates() + states[1].u.reshape(-1, 3)
    assert cloth[:, 2].min() < TOP  # the edges hang over the sides
    assert np.all(np.diff(energies) <= 1e-12 * abs(energies[0])), np.diff(energies)


def test_pinned_vertices_in_contact_stay_on_their_targets():
    """The cube held by its top face (and its base): the cloth lands on pinned vertices.
    Their rows are Dirichlet rows x - u_bc, so the barrier's push on them is dropped and
    they stay at zero displacement (to round-off) while pairs hold the cloth above them."""
    top_pin = {"min": [-1.0, -1.0, TOP - 1e-6], "max": [1.0, 1.0, TOP + 1e-6]}
    solid = _solid(pin=[_solid()["pin"][0], top_pin])
    sim = _simulation(solid, _shell())
    pinned = _pinned(sim.parts[0])
    states = sim.initial_state()
    pairs = 0
    for _ in range(5):
        states, _ = sim.step(states, 0.01)
        pairs = max(pairs, sim.problem.ipc.num_pairs)
        assert np.abs(states[0].u[pinned]).max() < 1e-12
    assert pairs > 0


def _momentum(sim: JointSimulation, states) -> np.ndarray:
    """sum over both bodies of M v, per axis (kg m/s)."""
    total = np.zeros(3)
    for part, s in zip(sim.parts, states):
        M = fem_petsc.assemble_matrix(part.mass_form)
        M.assemble()
        v = M.createVecRight()
        v.array[:] = s.v[: v.array.size]
        Mv = v.duplicate()
        M.mult(v, Mv)
        total += Mv.array.reshape(-1, 3).sum(axis=0)
    return total


def test_free_collision_keeps_the_total_momentum():
    """No gravity, no pins: the cloth thrown down at 0.3 m/s onto the free cube at rest.
    The barrier and the elastic forces are internal, so sum M v of both bodies is kept to
    round-off while they collide (implicit Euler: each full Newton step leaves the summed
    residual at zero)."""
    sim = _simulation(_solid(gravity=None, pin=None),
                      _shell(gravity=None, initial={"velocity": [0.0, 0.0, -0.3]}))
    states = sim.initial_state()
    p0 = _momentum(sim, states)
    assert p0[2] < 0
    pairs = 0
    for _ in range(6):
        states, _ = sim.step(states, 0.01)
        pairs = max(pairs, sim.problem.ipc.num_pairs)
        assert np.abs(_momentum(sim, states) - p0).max() <= 1e-10 * abs(p0[2])
    assert pairs > 0
    # the cube was pushed: momentum moved from the cloth to the cube
    cube_v = states[0].v.reshape(-1, 3)[:, 2].mean()
    assert cube_v < -1e-3


@pytest.mark.parametrize("change, message", [
    ({"shell": {"thickness": T, "bending_model": "kirchhoff_love"}, "element": {"degree": 2}},
     "P1"),
    ({"time": {"dt": 0.01, "steps": 10, "integrator": "newmark"}}, "time.integrator"),
    ({"contact": None}, "[contact]"),
    ({"time": {"dt": 0.02, "steps": 10, "integrator": "implicit_euler"}}, "[time]"),
])
def test_bad_combinations_are_refused_in_one_line(change, message):
    with pytest.raises(SceneError) as err:
        shell = _shell(**change)
        solid = _solid()
        if "time" in change and change["time"]["integrator"] == "newmark":
            solid = _solid(time=change["time"])
        _simulation(solid, shell)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_mixed_solid_is_refused_in_one_line():
    with pytest.raises(SceneError) as err:
        _simulation(_solid(element={"formulation": "mixed"},
                           material={"model": "neohookean", "youngs_modulus": 2.0e4,
                                     "poisson_ratio": 0.3, "density": 500.0}), _shell())
    assert "formulation" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.mpi
def test_two_ranks_equal_serial(tmp_path):
    """The cloth on the cube with friction (tests/mpi/mpi_shell_solid_check.py) on 2 ranks:
    every step's total energy and both bodies' final displacements equal the serial run's to
    1e-8, with pairs between the bodies."""
    import subprocess
    import sys

    from conftest import ROOT, clean_environment, mpirun_command

    script = ROOT / "tests" / "mpi" / "mpi_shell_solid_check.py"
    results = {}
    for ranks in (1, 2):
        prefix = [] if ranks == 1 else mpirun_command(ranks)
        if prefix is None:
            pytest.skip("mpirun not available")
        out = tmp_path / f"ranks{ranks}.npz"
        r = subprocess.run([*prefix, sys.executable, str(script), str(out)],
                           capture_output=True, text=True, timeout=900,
                           env=clean_environment(), cwd=ROOT)
        assert r.returncode == 0, r.stdout + r.stderr
        results[ranks] = dict(np.load(out))
    one, two = results[1], results[2]
    assert one["pairs"][-1] > 0
    assert np.allclose(two["energy"], one["energy"], rtol=1e-8, atol=0.0)
    for body in ("solid", "shell"):
        du = np.linalg.norm(two[body] - one[body])
        assert du <= 1e-8 * np.linalg.norm(one[body]), body


# -- the scene file: a shell [[body]] beside solid ones (fem-anim run) ---------------------

DRAPE_SOFT = """name = "drape_soft"
[time]
integrator = "implicit_euler"
dt = 0.01
steps = 6
[gravity]
acceleration = [0.0, 0.0, -9.81]
[contact]
dhat = 0.001
friction = 0.3
[output]
render = false
[[body]]
name = "cube"
mesh = { shape = "box", size = [0.1, 0.1, 0.1], origin = [-0.05, -0.05, 0.0], element_size = 0.05 }
material = { model = "neohookean", youngs_modulus = 2.0e4, poisson_ratio = 0.3, density = 500.0 }
[[body.pin]]
min = [-1.0, -1.0, -1.0e-6]
max = [1.0, 1.0, 1.0e-6]
[[body]]
name = "cloth"
offset = [0.0, 0.0, 0.103]
mesh = { shape = "sheet", size = [0.16, 0.16], origin = [-0.08, -0.08, 0.0], element_size = 0.04 }
material = { model = "stvk", youngs_modulus = 1.0e5, poisson_ratio = 0.3, density = 300.0 }
shell = { thickness = 0.001 }
"""


def _cli(tmp_path, name: str, text: str, *args) -> tuple[int, list[str]]:
    """``fem-anim run`` of a scene text in this process: (exit code, stderr lines)."""
    import contextlib
    import io

    from fem_anim.cli import main as cli_main

    scene = tmp_path / f"{name}.toml"
    scene.write_text(text)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli_main(["run", str(scene), "-o", str(tmp_path / name), "--quiet", *args])
    return code, [line for line in err.getvalue().splitlines() if line.strip()]


def _trajectory(path) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Rest points, cells and every frame's displacement of a written trajectory."""
    import h5py

    with h5py.File(path, "r") as h5:
        count = len(h5.attrs["times"])
        return (np.asarray(h5["data0"]), np.asarray(h5["data1"]),
                [np.asarray(h5[f"data{k + 2}"]) for k in range(count)])


def test_scene_file_with_a_shell_body_runs_intersection_free(tmp_path):
    """``fem-anim run`` of a cloth [[body]] (with shell = {...}) beside a soft cube: both
    trajectories hold every step; in no frame does the sheet cross the cube's boundary (the
    independent check on both meshes' frames); stats and summary count the steps; the
    run's steps are the Python API's (same displacements)."""
    import json

    import meshio

    code, err = _cli(tmp_path, "drape", DRAPE_SOFT)
    assert code == 0, err
    out = tmp_path / "drape"
    Xs, cube_cells, us = _trajectory(out / "solids.h5")
    Xc, cloth_cells, uc = _trajectory(out / "shell.h5")
    assert len(us) == len(uc) == 7
    tris = np.concatenate([boundary_triangles(cube_cells), cloth_cells + len(Xs)])
    for a, b in zip(us, uc):
        assert not intersecting(np.concatenate([Xs + a, Xc + b]), tris)
    assert (Xc + uc[-1])[:, 2].min() < TOP  # draped over the edges
    stats = (out / "stats.csv").read_text().splitlines()
    assert len(stats) == 7
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 6 and not summary["energy"]["flagged"]
    final = meshio.read(out / "final_shell.vtu")
    assert np.array_equal(final.point_data["displacement"], uc[-1])
    # the seen surface (trajectory.h5, what the renderer draws): both meshes' points, the
    # cube's boundary and the cloth, every frame the two parts' frames side by side
    X, seen, u = _trajectory(out / "trajectory.h5")
    assert np.array_equal(X, np.concatenate([Xs, Xc]))
    assert np.array_equal(np.sort(seen, axis=1), np.sort(tris, axis=1))
    assert all(np.array_equal(f, np.concatenate([a, b])) for f, a, b in zip(u, us, uc))
    # the same steps through the Python API
    from fem_anim.scene import load_scene
    from fem_anim.simulation.joint_loop import JointSimulation

    sim = JointSimulation.from_scene(load_scene(tmp_path / "drape.toml"))
    states = sim.initial_state()
    for _ in range(6):
        states, _ = sim.step(states, 0.01)
    cloth = sim.parts[1].V.tabulate_dof_coordinates() + states[1].u.reshape(-1, 3)
    order = np.lexsort(np.round(Xc, 9).T[::-1])
    mine = np.lexsort(np.round(sim.parts[1].V.tabulate_dof_coordinates(), 9).T[::-1])
    assert np.abs(cloth[mine] - (Xc + uc[-1])[order]).max() < 1e-12


def test_python_api_runs_a_shell_body_scene(tmp_path):
    """``fem_anim.run`` of the scene: the Run reads the seen surface of both meshes (6
    steps, 7 frames, the cloth lowered); ``Simulation`` (one mesh) refuses the scene in one
    line, naming the way to run it."""
    import fem_anim
    from fem_anim.errors import FemAnimError
    from fem_anim.simulation.loop import Simulation

    scene = fem_anim.Scene.from_toml(DRAPE_SOFT)
    with fem_anim.run(scene, tmp_path / "api") as run:
        assert len(run.times) == 7 and len(run.stats) == 6
        X, u = run.points, run.displacement(-1)
        assert X.shape[1] == 3 and u[:, 2].min() < -1e-3  # the cloth fell
    with pytest.raises(FemAnimError) as err:
        Simulation(scene)
    assert "fem-anim run" in str(err.value) and "\n" not in str(err.value)


def test_a_shell_body_run_is_drawn_in_3d(tmp_path):
    """The renderer reads the seen surface of a scene with a shell [[body]] as a surface in
    3D (its scene.json's body has a shell table), as a [shell] scene's."""
    import json

    from fem_anim.render.frames import space_dim

    scene = {"mesh": {"dim": 3}, "body": [{"name": "cube"}, {"name": "cloth",
                                                              "shell": {"thickness": T}}]}
    (tmp_path / "scene.json").write_text(json.dumps({"scene": scene}))
    assert space_dim("triangle", tmp_path) == 3


BAD_JOINT = {
    "two shells": (DRAPE_SOFT + DRAPE_SOFT[DRAPE_SOFT.index('[[body]]\nname = "cloth"'):]
                   .replace('"cloth"', '"cloth2"'), "one [[body]] may have a shell"),
    "kirchhoff-love": (DRAPE_SOFT.replace("shell = { thickness = 0.001 }",
                                          "shell = { thickness = 0.001, bending_model = "
                                          "\"kirchhoff_love\" }"), "needs P1"),
    "newmark": (DRAPE_SOFT.replace('integrator = "implicit_euler"', 'integrator = "newmark"'),
                "time.integrator"),
    "mixed": (DRAPE_SOFT.replace("[output]", "[element]\nformulation = \"mixed\"\n[output]"),
              "formulation"),
    "wind": (DRAPE_SOFT + "[wind]\nvelocity = [1.0, 0.0, 0.0]\n", "[wind]"),
    "rotated shell": (DRAPE_SOFT.replace("offset = [0.0, 0.0, 0.103]",
                                         "offset = [0.0, 0.0, 0.103]\nrotation = [0.0, 0.0, 10.0]"),
                      "rotation"),
    "no self contact": (DRAPE_SOFT.replace("friction = 0.3", "friction = 0.3\nself = false"),
                        "contact.self"),
    "top-level shell": (DRAPE_SOFT + "[shell]\nthickness = 0.001\n", "body[i].shell"),
    "resume": (DRAPE_SOFT, "nothing to resume"),
}


@pytest.mark.parametrize("case", sorted(BAD_JOINT))
def test_bad_shell_with_solids_is_one_line_exit_2(case, tmp_path):
    """Each refused combination ends with exit code 2 and one ``fem-anim: error:`` line."""
    text, words = BAD_JOINT[case]
    args = ("--resume", str(tmp_path / "bad")) if case == "resume" else ()
    code, err = _cli(tmp_path, "bad", text, *args)
    assert code == 2
    assert len(err) == 1 and err[0].startswith("fem-anim: error: "), err
    assert words in err[0], err[0]


@pytest.mark.mpi
def test_scene_file_on_two_ranks_equals_serial(tmp_path):
    """``fem-anim run`` of the scene file on 1 and 2 ranks: every frame of both trajectories
    (gathered in input vertex order) and every step's total energy agree to 1e-8."""
    import csv

    from conftest import run_on_one_and_more_ranks

    scene = tmp_path / "drape.toml"
    scene.write_text(DRAPE_SOFT)
    outs = run_on_one_and_more_ranks(scene, tmp_path)
    for name in ("solids", "shell"):
        _, _, one = _trajectory(outs[1] / f"{name}.h5")
        _, _, two = _trajectory(outs[2] / f"{name}.h5")
        assert len(one) == len(two) == 7
        scale = np.abs(one[-1]).max()
        assert max(np.abs(a - b).max() for a, b in zip(one, two)) <= 1e-8 * scale, name
    rows = [list(csv.DictReader(open(outs[n] / "stats.csv"))) for n in (1, 2)]
    energy = np.array([[float(r["total_energy"]) for r in rs] for rs in rows])
    assert np.allclose(energy[1], energy[0], rtol=1e-8, atol=0.0)


@pytest.mark.parametrize("integrator", ["implicit_euler", "bdf2"])
def test_bodies_apart_step_as_their_own_runs(integrator):
    """Far apart (no pair), the joint step decouples: 6 steps of the cube (pinned, sagging)
    and the cloth (falling, held at one corner) equal each body's own one-mesh run
    (:class:`fem_anim.simulation.loop.Simulation` on its own scene; the cloth's with its
    self contact) to 1e-9, both solved to round-off."""
    from fem_anim.simulation.loop import Simulation

    tight = {"stopping": "norm", "petsc": {"snes_atol": 1e-13, "snes_rtol": 1e-14}}
    time_cfg = {"dt": 0.01, "steps": 6, "integrator": integrator}
    corner = [{"min": [-0.5, -0.5, 0.19], "max": [-0.45, -0.45, 0.21]}]
    solid = _solid(time=time_cfg, solver=tight)
    shell = _shell(z=0.2, time=time_cfg, solver=tight, pin=corner,
                   mesh={"shape": "sheet", "size": [0.16, 0.16], "origin": [-0.5, -0.5, 0.2],
                         "element_size": 0.04})
    joint = _simulation(solid, shell)
    states = joint.initial_state()
    for _ in range(6):
        states, _ = joint.step(states, 0.01)
    assert joint.problem.ipc.num_pairs == 0
    for k, scene in enumerate((solid, shell)):
        alone = Simulation(Scene.from_dict(scene))
        state = alone.initial_state()
        for _ in range(6):
            state, _ = alone.step(state, 0.01)
        scale = np.abs(state.u).max()
        assert scale > 1e-4
        assert np.abs(states[k].u - state.u).max() <= 1e-9 * scale, k


def test_block_storage_solves_the_joint_step(tmp_path):
    """A preset storing 3 x 3 blocks (``cg-icc``: ``mat_type = baij``) gives the joint
    Hessian in blocks and the run the direct solver's steps (to the stopping tests)."""
    finals = []
    for preset in ("cholesky", "cg-icc"):
        code, err = _cli(tmp_path, f"drape_{preset}", DRAPE_SOFT, "--solver", preset)
        assert code == 0, err
        finals.append(_trajectory(tmp_path / f"drape_{preset}" / "shell.h5")[2][-1])
    assert np.abs(finals[1] - finals[0]).max() < 1e-6 * np.abs(finals[0]).max()


def test_cloth_lands_on_itself_beside_a_solid(tmp_path):
    """The shell's self contact inside the joint barrier: the U-folded strip of
    tests/test_shell_contact.py (lower leg and wall held, no bending stiffness) beside a cube
    far away. Its upper leg falls onto the lower leg: cloth-cloth pairs form, no vertex of
    the upper leg over the lower one comes nearer than t (the joint d_min), and it ends
    within t + d_hat, as in the shell's own scene; no frame has a crossing."""
    from test_shell_contact import _u_fold

    length, gap = 0.1, 0.02
    points = _u_fold(tmp_path / "fold.obj", length, gap)
    time_cfg = {"dt": 0.01, "steps": 25, "integrator": "implicit_euler"}
    solid = _solid(time=time_cfg, mesh={"shape": "box", "size": [0.1, 0.1, TOP],
                                        "origin": [0.5, 0.5, 0.0], "element_size": 0.05})
    shell = _shell(time=time_cfg, mesh={"shape": "file", "file": str(tmp_path / "fold.obj")},
                   shell={"thickness": T, "bending": 0.0}, damping={"alpha": 5.0},
                   pin=[{"min": [-0.01, -0.01, -0.001], "max": [length + 0.001, 0.07, 0.001]},
                        {"min": [length - 0.001, -0.01, -0.001],
                         "max": [length + 0.001, 0.07, gap - 0.001]}])
    sim = _simulation(solid, shell)
    X = sim.parts[1].V.tabulate_dof_coordinates()
    _, tris, _ = _union_surface(sim)
    upper = np.isclose(X[:, 2], gap) & (X[:, 0] < length - 1e-9)
    assert upper.sum() > 0 and len(points) == len(X)
    states = sim.initial_state()
    lowest, pairs = [], 0
    for _ in range(25):
        states, _ = sim.step(states, 0.01)
        pairs = max(pairs, sim.problem.ipc.num_pairs)
        x = X + states[1].u.reshape(-1, 3)
        over = upper & (x[:, 0] > 0) & (x[:, 0] < length)
        lowest.append(x[over, 2].min())
        assert not intersecting(_vertex_positions(sim, states), tris)
    assert pairs > 0
    assert min(lowest) >= T * (1 - 1e-9)
    assert lowest[-1] < T + DHAT
