"""The contact energy a run reports while friction acts, recomputed from its files.

The contract (:mod:`fem_anim.problem.reported_energies`): the ``contact`` column of
``stats.csv`` is the stored barrier energy of the frame's positions, kappa/d_hat sum_v A_v
b(d(x_v)) for obstacles (:mod:`fem_anim.reference.obstacle_barrier`), and holds nothing of
the friction potential (lagged friction dissipates: it is no stored energy). A block slides
on a frictional plane, its bottom face inside the barrier's range; each step's reported
contact energy is recomputed from the positions written to ``trajectory.xdmf`` by the numpy
oracle, and the friction potential of the same step (also from the frames, with the
oracle) is shown to be large against the tolerance, so adding it would be seen.
"""

from __future__ import annotations

import csv

import meshio
import numpy as np
import pytest
from mpi4py import MPI

from fem_anim.cli import main
from fem_anim.reference import obstacle_barrier as oracle

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial: one CLI run")

YOUNG, DHAT, MU, EPSV, DT, STEPS = 1e5, 0.01, 0.5, 1e-3, 0.01, 5
PLANE = {"type": "plane", "point": [0.0, 0.0, -0.004], "normal": [0.0, 0.0, 1.0],
         "dhat": DHAT, "stiffness": YOUNG}

SCENE = f"""
name = "slide"
mesh = {{ shape = "box", size = [0.2, 0.2, 0.1], divisions = [2, 2, 1] }}
material = {{ youngs_modulus = {YOUNG}, density = 1000 }}
gravity = {{ acceleration = [0, 0, -9.81] }}
initial = {{ velocity = [1.0, 0.0, 0.0] }}
output = {{ render = false }}
[time]
dt = {DT}
steps = {STEPS}
integrator = "implicit_euler"
[solver.petsc]
snes_rtol = 1e-12
[[obstacle]]
type = "plane"
point = {PLANE["point"]}
normal = {PLANE["normal"]}
dhat = {DHAT}
friction = {MU}
epsv = {EPSV}
"""


def test_reported_contact_energy_is_the_barrier_of_the_written_positions(tmp_path):
    path = tmp_path / "slide.toml"
    path.write_text(SCENE)
    out = tmp_path / "out"
    assert main(["run", "-q", str(path), "-o", str(out)]) == 0
    rows = list(csv.DictReader(open(out / "stats.csv")))
    with meshio.xdmf.TimeSeriesReader(str(out / "trajectory.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        frames = [reader.read_data(k)[1]["displacement"] for k in range(reader.num_steps)]
    tets = next(c.data for c in cells if c.type == "tetra")
    assert len(rows) == STEPS and len(frames) == STEPS + 1
    x = [(points + u).ravel() for u in frames]
    friction_seen = 0.0
    for k, row in enumerate(rows, 1):
        barrier = oracle.contact_energy(points, tets, x[k], PLANE)
        friction = oracle.friction_energy(points, tets, x[k], x[k - 1],
                                          dict(PLANE, friction=MU), EPSV * DT)
        assert barrier > 0.0  # the bottom face stays inside the barrier's range
        assert float(row["contact"]) == pytest.approx(barrier, rel=1e-9, abs=1e-14), k
        friction_seen = max(friction_seen, friction / barrier)
    # friction acts: its potential is a sizeable fraction of the barrier energy, far above
    # the tolerance above, and the block slows down
    assert friction_seen > 1e-3
    assert frames[-1][:, 0].mean() < 1.0 * DT * STEPS


#: Two soft cubes thrown at each other with a sliding component (friction acts in the
#: impact), the barrier stiffness fixed so that the energy is recomputable from the scene.
CUBES = """
name = "cubes_friction"
[time]
dt = 0.01
steps = 3
integrator = "implicit_euler"
[output]
render = false
[contact]
dhat = 0.005
stiffness = {kappa}
friction = 0.5
[[body]]
name = "left"
offset = [-0.11, 0, 0]
mesh = {{ shape = "box", size = [0.1, 0.1, 0.1], divisions = [2, 2, 2] }}
material = {{ youngs_modulus = 1e5, density = 1000 }}
initial = {{ velocity = [0.5, 0.3, 0] }}
[[body]]
name = "right"
offset = [0.0, -0.02, 0]
mesh = {{ shape = "box", size = [0.1, 0.1, 0.1], divisions = [2, 2, 2] }}
material = {{ youngs_modulus = 2e5, density = 800 }}
initial = {{ velocity = [-0.5, -0.3, 0] }}
"""


@pytest.mark.slow  # ~20 s of CPU (60 Newton iterations with 45-50 contact pairs)
def test_reported_ipc_energy_is_ipctks_barrier_of_the_written_positions(tmp_path):
    """Between bodies: kappa B(x) by ipctk itself on a surface taken from the written
    tetrahedra (:func:`fem_anim.contact.intersection.surface_collision_mesh`), at the frames'
    positions: the step's lagged friction potential is not in it. (The obstacle test above
    is the default run's variant of this check.)"""
    import ipctk

    from fem_anim.contact.intersection import surface_collision_mesh

    kappa = 1e5
    path = tmp_path / "cubes.toml"
    path.write_text(CUBES.format(kappa=kappa))
    out = tmp_path / "out"
    assert main(["run", "-q", str(path), "-o", str(out)]) == 0
    rows = list(csv.DictReader(open(out / "stats.csv")))
    with meshio.xdmf.TimeSeriesReader(str(out / "trajectory.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        frames = [reader.read_data(k)[1]["displacement"] for k in range(reader.num_steps)]
    tets = next(c.data for c in cells if c.type == "tetra")
    mesh, used = surface_collision_mesh(points, tets)
    rest = mesh.rest_positions
    barrier = ipctk.BarrierPotential(0.005, 1.0, True)
    active = 0
    for k, row in enumerate(rows, 1):
        x = np.asfortranarray(rest + frames[k][used])
        collisions = ipctk.NormalCollisions()
        collisions.use_area_weighting = True
        collisions.build(mesh, x, 0.005)
        expected = kappa * barrier(collisions, mesh, x)
        active += expected > 0.0
        assert float(row["contact"]) == pytest.approx(expected, rel=1e-9, abs=1e-14), k
    assert active >= 2, "the cubes no longer meet within the run"
