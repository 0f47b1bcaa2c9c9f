"""Several bodies in contact through the IPC Toolkit: physics, not only running.

Every run here is checked frame by frame for intersections by an independent test: the
boundary triangles are taken from the input tetrahedra in numpy (faces of one cell only),
the positions from the frames on disk or from the states, and ipctk's ``has_intersections``
must be false on each.
"""

from __future__ import annotations

import json

import ipctk
import meshio
import numpy as np
import pytest
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from conftest import step_taylor_remainders
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.cli import main
from fem_anim.contact.intersection import crossed_frames
from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation

#: Two soft cubes of different materials thrown at each other, the right one turned 10 deg.
TWO_CUBES = """
name = "two_cubes"
[time]
dt = 0.01
steps = {steps}
integrator = "implicit_euler"
[solver.petsc]
snes_atol = 1e-11
snes_rtol = 1e-14
[contact]
dhat = 0.005
[[body]]
name = "left"
offset = [-0.11, 0, 0]
mesh = {{ shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.05 }}
material = {{ youngs_modulus = 1e5, density = 1000 }}
initial = {{ velocity = [1.0, 0.2, 0] }}
[[body]]
name = "right"
offset = [0.03, 0.0, 0]
rotation = [0, 0, 10]
mesh = {{ shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.05 }}
material = {{ youngs_modulus = 2e5, density = 800 }}
initial = {{ velocity = [-1.0, 0, 0] }}
"""



def intersection_free(points: np.ndarray, cells: np.ndarray, frames) -> list[bool]:
    """For each displacement in ``frames``: no surface triangle crosses another (the surface
    from the tetrahedra alone: :mod:`fem_anim.contact.intersection`, not the contact code's)."""
    crossed = set(crossed_frames(points, cells, frames))
    return [k not in crossed for k in range(len(frames))]


def scene_file(tmp_path, steps: int, text: str = TWO_CUBES):
    path = tmp_path / "two_cubes.toml"
    path.write_text(text.format(steps=steps))
    return path


def momentum(sim: Simulation, M: PETSc.Mat, v: np.ndarray) -> np.ndarray:
    """P = sum over dofs of each axis of M v (collective)."""
    vec, Mv = M.createVecs()
    vec.array[:] = v[: vec.getLocalSize()]
    M.mult(vec, Mv)
    out = np.array([Mv.array.reshape(-1, 3)[:, i].sum() for i in range(3)])
    for obj in (vec, Mv):
        obj.destroy()
    return sim.comm.allreduce(out, op=MPI.SUM)


def test_two_cubes_conserve_momentum_through_the_impact(tmp_path):
    """Implicit Euler conserves M v exactly when the forces sum to zero: elastic forces of
    each body and the barrier's pair forces (translation-invariant energies) do. Through
    the impact (pairs active) the momentum stays the initial one to 1e-8 relative."""
    sim = Simulation(load_scene(scene_file(tmp_path, 14)))
    p = sim.problem
    M = fem_petsc.assemble_matrix(p.mass_form)
    M.assemble()
    state = sim.initial_state()
    P0 = momentum(sim, M, state.v)
    assert P0[0] > 0 and P0[1] > 0  # the left cube is heavier; it also moves in y
    states, pairs = [state], []
    for _ in range(14):
        state, _ = sim.step(state, 0.01)
        states.append(state)
        pairs.append(sim._contact_stats()["contact_pairs"])
        P = momentum(sim, M, state.v)
        assert np.linalg.norm(P - P0) <= 1e-8 * np.linalg.norm(P0), (len(states), P, P0)
    assert max(pairs) > 20 and pairs[-1] == 0  # they met, and they parted
    frames = [sim.gather.gather(s.u) for s in states]
    if sim.comm.rank == 0:
        u = [f.reshape(-1, 3) for f in frames]
        assert all(intersection_free(sim.domain.points, sim.domain.cells, u))
    M.destroy()


def test_cli_run_has_no_intersection_on_any_frame(tmp_path):
    """The run's frames read back from trajectory.xdmf are all intersection free, and
    stats.csv reports the contact time and pairs."""
    out = tmp_path / "out"
    assert main(["run", "-q", "-o", str(out), "--set", "output.render=false",
                 str(scene_file(tmp_path, 8))]) == 0
    with meshio.xdmf.TimeSeriesReader(str(out / "trajectory.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        frames = [reader.read_data(k)[1]["displacement"] for k in range(reader.num_steps)]
    tets = next(c.data for c in cells if c.type == "tetra")
    assert len(frames) == 9
    assert all(intersection_free(points, tets, frames))
    import csv

    rows = list(csv.DictReader(open(out / "stats.csv")))
    assert max(int(r["contact_pairs"]) for r in rows) > 0
    assert all(float(r["contact_s"]) > 0 for r in rows)


def test_barrier_taylor_inside_the_step_objective(tmp_path):
    """At a state with active pairs, the assembled objective's gradient and (unprojected)
    Hessian pass Taylor tests: the remainders fall as O(h^2)."""
    sim = Simulation(load_scene(scene_file(tmp_path, 2)))
    p = sim.problem
    state = sim.initial_state()
    for _ in range(2):
        state, _ = sim.step(state, 0.01)
    assert sim._contact_stats()["contact_pairs"] > 0
    p.ipc.projection = ipctk.PSDProjectionMethod.NONE
    x = p.x_work.duplicate()
    x.array[:] = state.u[: x.getLocalSize()]
    rng = np.random.default_rng(0)
    dx = x.duplicate()
    dx.array[:] = rng.standard_normal(dx.getLocalSize())
    alpha = p.ipc.step_bound(-dx.array)  # keep x + h dx clear of contact
    p.set_state(x)
    dx.scale(0.05 * alpha)
    first, second = step_taylor_remainders(p, sim.minimiser.A, x, dx)
    for remainders in (first, second):
        rates = np.log2(np.array(remainders[:-1]) / np.array(remainders[1:]))
        assert np.all(rates > 1.8), remainders


@pytest.mark.mpi
def test_contact_run_under_mpi_equals_serial(tmp_path):
    """mpirun -n 2 gives the serial stats and final displacement to 1e-8 relative."""
    from test_mpi_runs import assert_same_run, run

    path = scene_file(tmp_path, 5)
    for ranks in (1, 2):
        r = run(["run", "-q", "--set", "output.render=false", "-o", str(tmp_path / f"n{ranks}"),
                 str(path)], tmp_path, ranks)
        assert r.returncode == 0, r.stderr
    assert_same_run(tmp_path / "n1", tmp_path / "n2")
    import csv

    pairs = [[int(r["contact_pairs"]) for r in csv.DictReader(open(tmp_path / f"n{n}" /
                                                                  "stats.csv"))] for n in (1, 2)]
    assert pairs[0] == pairs[1] and max(pairs[0]) > 20  # through the impact


def body_dofs(problem, k: int) -> np.ndarray:
    """Owned vertex (block) indices of body k."""
    from dolfinx import fem

    cells = np.flatnonzero(problem.cell_body == k).astype(np.int32)
    blocks = compat.dofs_of_cells(problem.V, cells)
    return blocks[blocks < problem.V.dofmap.index_map.size_local]


def run_states(sim: Simulation, steps: int, h: float) -> list:
    state = sim.initial_state()
    states = [state]
    for _ in range(steps):
        state, _ = sim.step(state, h)
        states.append(state)
    return states


def assert_intersection_free(sim: Simulation, states) -> None:
    frames = [sim.gather.gather(s.u) for s in states]
    if sim.comm.rank == 0:
        u = [f.reshape(-1, sim.problem.d) for f in frames]
        assert all(intersection_free(sim.domain.points, sim.domain.cells, u))


STACK = """
name = "stack"
[time]
dt = 0.04
steps = 25
integrator = "implicit_euler"
[gravity]
acceleration = [0, 0, -9.81]
[contact]
dhat = 0.001
[[obstacle]]
type = "plane"
normal = [0, 0, 1]
dhat = 0.001
[[body]]
name = "bottom"
offset = [0, 0, 0.002]
mesh = { shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.05 }
material = { youngs_modulus = 1e5, density = 500 }
[[body]]
name = "top"
offset = [0.02, 0.02, 0.104]
mesh = { shape = "box", size = [0.06, 0.06, 0.06], element_size = 0.03 }
material = { youngs_modulus = 5e4, density = 1000 }
"""


def test_stack_at_rest_carries_the_weights(tmp_path):
    """A cube resting on another on the ground: once settled, the barrier between them
    pushes the top cube up with its weight m_top g, and the ground's barrier pushes the
    pair up with the total weight, each to 0.1 % (what is left is the last steps' inertia)."""
    import ufl
    from dolfinx import fem

    path = tmp_path / "stack.toml"
    path.write_text(STACK)
    sim = Simulation(load_scene(path))
    p = sim.problem
    states = run_states(sim, 25, 0.04)
    assert_intersection_free(sim, states)
    p.u.x.array[:] = states[-1].u
    g = 9.81
    masses = [0.5 * 0.1 ** 3 * 1000, 1000 * 0.06 ** 3]  # kg: bottom, top
    b = p.create_vector()
    b.set(0.0)
    p.ipc.add_gradient(b, 1.0)  # kappa grad B: minus the contact forces
    top = body_dofs(p, 1)
    lift = -sim.comm.allreduce(b.array.reshape(-1, 3)[top, 2].sum(), op=MPI.SUM)
    print(f"lift {lift:.6g} N for a weight {masses[1] * g:.6g} N")
    assert lift == pytest.approx(masses[1] * g, rel=1e-3)
    v = ufl.TestFunction(p.V)
    ground = fem.petsc.assemble_vector(fem.form(ufl.derivative(p.contact.energy, p.u, v)))
    ground.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    reaction = -sim.comm.allreduce(ground.array.reshape(-1, 3)[:, 2].sum(), op=MPI.SUM)
    print(f"ground {reaction:.6g} N for a weight {sum(masses) * g:.6g} N")
    assert reaction == pytest.approx(sum(masses) * g, rel=1e-3)
    assert max(abs(states[-1].v)) < 1e-2  # at rest


TILT = """
name = "tilt"
[time]
dt = 0.01
steps = 20
integrator = "implicit_euler"
[gravity]
acceleration = [0, 0, -9.81]
[contact]
dhat = 0.001
friction = 0.5
epsv = 1e-3
[[body]]
name = "slope"
rotation = [0, {angle}, 0]
mesh = {{ shape = "box", size = [0.4, 0.2, 0.05], element_size = 0.05 }}
material = {{ youngs_modulus = 1e6, density = 1000 }}
[[body.pin]]
min = [-1, -1, -1]
max = [1, 1, 1]
[[body]]
name = "block"
offset = {offset}
rotation = [0, {angle}, 0]
mesh = {{ shape = "box", size = [0.05, 0.05, 0.05], element_size = 0.05 }}
material = {{ youngs_modulus = 1e5, density = 1000 }}
"""


@pytest.mark.parametrize("angle", [15.0, 40.0])
def test_block_on_a_slope_sticks_below_the_friction_angle(tmp_path, angle):
    """mu = 0.5 (friction angle 26.6 deg): at 15 deg the block stays (it moves less than
    3 % of a frictionless slide: the fall onto the slope and IPC's creep below eps_v), at
    40 deg it slides with a = g (sin - mu cos), measured over its last 0.1 s, to 1 %."""
    from fem_anim.mesh.bodies import rotation_matrix

    R = rotation_matrix([0, angle, 0], 3)
    offset = R @ np.array([0.15, 0.075, 0.052])  # 2 mm above the slope
    path = tmp_path / "tilt.toml"
    path.write_text(TILT.format(angle=angle, offset=[float(v) for v in offset]))
    sim = Simulation(load_scene(path))
    states = run_states(sim, 20, 0.01)
    assert_intersection_free(sim, states)
    block = body_dofs(sim.problem, 1)
    tangent = R @ np.array([1.0, 0, 0])  # down the slope
    n = sim.comm.allreduce(block.size, op=MPI.SUM)

    def mean(values):  # the block's mean of a vertex field, along the slope
        return sim.comm.allreduce((values.reshape(-1, 3)[block] @ tangent).sum(), op=MPI.SUM) / n

    slide = mean(states[-1].u)
    accel = (mean(states[20].v) - mean(states[10].v)) / 0.1  # once it rests on the slope
    theta = np.radians(angle)
    coulomb = 9.81 * (np.sin(theta) - 0.5 * np.cos(theta))
    frictionless = 0.5 * 9.81 * np.sin(theta) * 0.2 ** 2
    print(f"angle {angle}: slide {slide:.4g} m (frictionless {frictionless:.4g} m), "
          f"acceleration {accel:.4g} m/s^2 (Coulomb {coulomb:.4g})")
    if angle < 26.5:  # what moves: the fall onto the slope (0.3 mm) and the eps_v creep
        assert abs(slide) < 0.03 * frictionless and abs(accel) < 0.01 * 9.81
    else:
        assert accel == pytest.approx(coulomb, rel=0.01)


FOLD = """
name = "fold"
[time]
dt = 0.02
steps = 40
integrator = "implicit_euler"
[gravity]
acceleration = [0, 0, -9.81]
[material]
youngs_modulus = 2e4
density = 1000
[mesh]
shape = "box"
origin = [0, 0, 0.002]
size = [0.6, 0.04, 0.04]
element_size = 0.02
[contact]
dhat = 0.001
[[obstacle]]
type = "plane"
normal = [0, 0, 1]
[[pin]]
name = "left"
min = [-0.01, -1, -1]
max = [0.35, 1, 1]
[[pin]]
name = "right"
min = [0.57, -1, -1]
max = [0.61, 1, 1]
angular_velocity = -6.283185307179586
axis = [0, 1, 0]
center = [0.45, 0.02, 0.04225]
until = 0.5
"""


def test_bar_folded_into_a_u_touches_itself_and_never_crosses(tmp_path):
    """One soft bar on the ground (a single body: self contact), its left half held, its
    right end turned half a turn up and over about a point just above the top face, so
    that it comes down 0.5 mm (< dhat) above the held half and the fold presses on it by
    gravity. Pairs appear only once the arms meet (none while the bar bends), and no frame
    read back from disk has an intersection. (Turned the other way the pins would drive
    the end through the ground: that run stops with a convergence error instead.)"""
    import csv

    path = tmp_path / "fold.toml"
    path.write_text(FOLD)
    out = tmp_path / "out"
    assert main(["run", "-q", "-o", str(out), "--set", "output.render=false", str(path)]) == 0
    rows = list(csv.DictReader(open(out / "stats.csv")))
    pairs = [int(r["contact_pairs"]) for r in rows]
    assert pairs[0] == 0 and min(pairs[-5:]) > 20
    with meshio.xdmf.TimeSeriesReader(str(out / "trajectory.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        frames = [reader.read_data(k)[1]["displacement"] for k in range(reader.num_steps)]
    tets = next(c.data for c in cells if c.type == "tetra")
    assert len(frames) == 41 and all(intersection_free(points, tets, frames))
    tip = points[:, 0] > 0.59  # the right end came over onto the held half
    assert np.all(points[tip, 0] + frames[-1][tip, 0] < 0.35)


def test_render_gives_each_body_its_colour_and_draws_the_ground(tmp_path):
    """``render.color_by = "body"``: the two cubes come out in the palette's first two
    colours (blue, orange), and the ground plane is drawn grey below them."""
    import imageio.v3 as iio

    text = TWO_CUBES + ('[render]\ncolor_by = "body"\noutputs = []\nshow_edges = false\n'
                        '[[obstacle]]\ntype = "plane"\nnormal = [0, 0, 1]\n'
                        'point = [0, 0, -0.05]\n')
    out = tmp_path / "out"
    assert main(["run", "-q", "-o", str(out), str(scene_file(tmp_path, 2, text))]) == 0
    image = iio.imread(out / "final.png").astype(int)
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    blue = np.count_nonzero((b > r + 60) & (b > g + 20))
    orange = np.count_nonzero((r > b + 100) & (r > g + 40))
    grey = np.count_nonzero((abs(r - g) < 8) & (abs(g - b) < 8) & (r > 120) & (r < 230))
    assert blue > 2000 and orange > 2000 and grey > 20000, (blue, orange, grey)


@pytest.mark.slow
def test_without_self_contact_the_folded_bar_has_no_pairs(tmp_path):
    """``contact.self = false`` keeps only pairs between different bodies: the fold that
    makes 48 pairs with self contact makes none (one body)."""
    import csv

    path = tmp_path / "fold.toml"
    path.write_text(FOLD)
    out = tmp_path / "out"
    assert main(["run", "-q", "-o", str(out), "--set", "output.render=false",
                 "--set", "contact.self=false", str(path)]) == 0
    rows = list(csv.DictReader(open(out / "stats.csv")))
    assert all(int(r["contact_pairs"]) == 0 for r in rows)


def test_body_materials_and_regions_act_on_their_own_cells(tmp_path):
    """Each body's material is its cells'; a [[body.region]] box covering both bodies
    changes only its own body's cells (those whose centroid lies in it)."""
    from dolfinx import mesh as dmesh

    text = TWO_CUBES.replace('initial = {{ velocity = [-1.0, 0, 0] }}\n',
                             'initial = {{ velocity = [-1.0, 0, 0] }}\n[[body.region]]\n'
                             'name = "soft"\nmin = [-1, -1, -1]\nmax = [1, 1, 0.05]\n'
                             'youngs_modulus = 1e3\n')
    sim = Simulation(load_scene(scene_file(tmp_path, 1, text)))
    p = sim.problem
    n = p.cell_body.size
    z = dmesh.compute_midpoints(sim.domain.mesh, 3, np.arange(n, dtype=np.int32))[:, 2]
    E = p.material_map.cell_values("youngs_modulus")
    low = z <= 0.05
    assert np.all(E[p.cell_body == 0] == 1e5)  # the box covers body 0 too: not its region
    assert np.all(E[(p.cell_body == 1) & low] == 1e3)
    assert np.all(E[(p.cell_body == 1) & ~low] == 2e5)
    assert np.any((p.cell_body == 1) & low) and np.any((p.cell_body == 1) & ~low)


def test_interrupted_contact_run_resumes_to_the_same_run(tmp_path):
    """SIGINT after the impact, then --resume: the stats equal an uninterrupted run's to
    1e-12. This needs every run to repeat to the last digit (ipctk on one thread: with its
    threaded sums two runs differed by a Newton iteration at step 2) and the checkpoint to
    keep the adaptive kappa's floor (here it stays at its first value; it is checked to be
    kept)."""
    import csv
    import signal

    from test_safety import checkpoint_meta, fem_anim, start, wait_for_rows

    path = scene_file(tmp_path, 14)
    args = ["run", "-q", "--set", "output.render=false", "--set", "output.checkpoint_every=100",
            str(path)]
    assert main(args + ["-o", str(tmp_path / "whole")]) == 0
    out = tmp_path / "cut"
    proc = start(args + ["-o", str(out)])
    wait_for_rows(out, 7, proc, timeout=300)
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=300)
    assert proc.returncode != 0
    assert checkpoint_meta(out / ".partial" / "checkpoint.npz")["contact"]["kappa_floor"] > 0.0
    done = fem_anim(args + ["--resume", str(out)], timeout=600)
    assert done.returncode == 0, done.stderr

    def rows(where):
        with open(where / "stats.csv") as f:
            return list(csv.DictReader(f))

    whole, resumed = rows(tmp_path / "whole"), rows(out)
    assert len(whole) == len(resumed) and max(int(r["contact_pairs"]) for r in whole) > 0
    for a, b in zip(whole, resumed):
        assert a["newton_its"] == b["newton_its"], a["step"]
        for key in ("kinetic", "elastic", "contact", "total_energy"):
            assert float(a[key]) == pytest.approx(float(b[key]), rel=1e-12, abs=1e-14), \
                (a["step"], key)
