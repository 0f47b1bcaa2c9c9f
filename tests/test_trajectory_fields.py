"""``output.fields``: the trajectory holds every dof of a P2 displacement, the velocity and a
mixed run's pressure, so a step's discrete equations (seed eq. 4) can be re-assembled from
the files alone; a resumed run writes the same fields.

The re-check maps the file's rows to the problem's dofs through the checkpoint's own dof
keys (:func:`fem_anim.simulation.checkpoint.dof_identity`), not through the writer's
:class:`~fem_anim.output.dof_gather.DofGather`: two independent namings of the same dofs.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from scenes import bar, make_scene, merge

H = 0.01
#: Runs in this process that read their files back: each process has its own tmp_path.
serial = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial: one run per process "
                            "(the two-rank case launches mpirun itself)")


def _p2_scene(tmp_path, fields, **overrides):
    scene = bar("p2bar", element={"degree": 2},
                gravity={"acceleration": [0.0, 0.0, -9.81]},
                time={"dt": H, "steps": 3, "integrator": "implicit_euler"},
                output={"render": False, "fields": fields})
    return make_scene(tmp_path, merge(scene, **overrides))


def _local(sim, V, nodes: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The file's rows as a local dof array of V (ghosts included), by the checkpoint's keys."""
    from fem_anim.simulation.checkpoint import dof_identity

    keys = dof_identity(V, sim.domain)
    base = sim.comm.allreduce(int(sim.domain.input_index.max(initial=-1)) + 1, op=MPI.MAX)
    file_keys = nodes[:, 0] * base + nodes[:, 1]
    order = np.argsort(file_keys)
    where = order[np.searchsorted(file_keys, keys, sorter=order)]
    assert np.array_equal(file_keys[where], keys)
    return np.asarray(rows)[where].ravel()


def _read(out, name: str, k: int):
    with h5py.File(out / "trajectory.h5", "r") as h5:
        return h5[f"{name}_nodes"][()], h5[f"{name}_dofs{k}"][()]


@serial
def test_p2_step_residual_recomputed_from_the_written_fields(tmp_path):
    """Each step of a P2 bar's run: stage the step objective from frame n's displacement
    and velocity (implicit Euler: y = u_n + h v_n), put frame n+1's displacement in, and
    the residual grad g over the free dofs is below 1e-6 of its largest force term."""
    from fem_anim.simulation.integrators import State
    from fem_anim.simulation.loop import Simulation

    scene = _p2_scene(tmp_path, ["displacement", "energy_density", "velocity"])
    sim = Simulation(scene)
    result = sim.run(tmp_path / "out", quiet=True)
    out = tmp_path / "out"
    assert len(result.rows) == 3  # one step per frame: frames are consecutive states
    p, integ = sim.problem, sim.integrator
    with h5py.File(out / "trajectory.h5", "r") as h5:
        vertex = [h5[f"data{k + 2}"][()] for k in range(4)]
        times = h5.attrs["times"]
    for n in range(3):
        nodes, u_rows = _read(out, "displacement", n)
        _, u_next_rows = _read(out, "displacement", n + 1)
        v_nodes, v_rows = _read(out, "velocity", n)
        assert np.array_equal(v_nodes, nodes)
        num_vertices = vertex[n].shape[0]
        assert nodes.shape[0] > num_vertices  # the edge dofs are there
        np.testing.assert_array_equal(u_rows[:num_vertices], vertex[n])
        u_n, v_n = _local(sim, p.V, nodes, u_rows), _local(sim, p.V, nodes, v_rows)
        u_next = _local(sim, p.V, nodes, u_next_rows)
        state = State(u=u_n, v=v_n, a=np.zeros_like(u_n), time=float(times[n]), step=n)
        p.stage(u_n, integ.predictor(H, state), integ.weight(H, state),
                float(times[n + 1]), H)
        x, r = p.x_work.duplicate(), p.x_work.duplicate()
        p.load_guess(u_next, x, apply_bcs=False)
        p.residual(None, x, r)
        scale = p.force_scale(x)
        assert scale > 0.0
        assert r.norm() <= 1e-6 * scale, (n, r.norm(), scale)
        # implicit Euler's velocity is the step's difference quotient
        _, v_next_rows = _read(out, "velocity", n + 1)
        np.testing.assert_allclose(v_next_rows, (u_next_rows - u_rows) / H, rtol=0,
                                   atol=1e-9 * np.abs(v_next_rows).max())


@serial
def test_mixed_pressure_written_satisfies_the_step_equations(tmp_path):
    """An incompressible P2-P1 bar: frame n+1's (u, p) read back from the file zeroes the
    mixed step's residual to 1e-6 of the pressure's own force term (the residual with
    p = 0), so the written pressure is the step's, in Pa (p = mu p~)."""
    from fem_anim import compat
    from fem_anim.simulation.integrators import State
    from fem_anim.simulation.loop import Simulation

    scene = _p2_scene(tmp_path, ["displacement", "velocity", "pressure"],
                      element={"degree": 2, "formulation": "mixed"},
                      material={"poisson_ratio": 0.5, "model": "stable_neohookean"},
                      solver={"preset": "ldlt"}, time={"dt": H, "steps": 2,
                                                       "integrator": "implicit_euler"})
    sim = Simulation(scene)
    result = sim.run(tmp_path / "out", quiet=True)
    assert len(result.rows) == 2
    out, p, integ = tmp_path / "out", sim.problem, sim.integrator
    with h5py.File(out / "trajectory.h5", "r") as h5:
        times = h5.attrs["times"]
    mu = float(p.mu.value)
    for n in range(2):
        nodes, u_rows = _read(out, "displacement", n)
        _, u_next_rows = _read(out, "displacement", n + 1)
        _, v_rows = _read(out, "velocity", n)
        q_nodes, p_rows = _read(out, "pressure", n + 1)
        assert q_nodes.shape[0] == u_rows.shape[0] - (nodes[:, 0] != nodes[:, 1]).sum()
        assert np.abs(p_rows).max() > 0.0
        u_n, v_n = _local(sim, p.V, nodes, u_rows), _local(sim, p.V, nodes, v_rows)
        u_next = _local(sim, p.V, nodes, u_next_rows)
        pressure = _local(sim, p.fields.Q, q_nodes, p_rows)
        state = State(u=u_n, v=v_n, a=np.zeros_like(u_n), time=float(times[n]), step=n)
        p.stage(u_n, integ.predictor(H, state), integ.weight(H, state),
                float(times[n + 1]), H)

        def residual(p_tilde):
            p.fields.set_displacement(u_next)
            p.fields.w.x.array[p.fields.p_dofs] = p_tilde
            x, r = p.x_work.duplicate(), p.x_work.duplicate()
            compat.petsc_vec(p.unknown).copy(x)
            p.residual(None, x, r)
            return r.norm()

        scale = residual(np.zeros_like(pressure))
        assert residual(pressure / mu) <= 1e-6 * scale, (n, residual(pressure / mu), scale)


def _interrupt_at(sim, step: int) -> None:
    """SIGINT this process once the run has taken ``step`` steps (it stops at that frame)."""
    import os
    import signal

    take = sim.timed_step

    def timed_step(state, dt):
        new, row = take(state, dt)
        if new.step == step:
            os.kill(os.getpid(), signal.SIGINT)
        return new, row

    sim.timed_step = timed_step


def _dof_datasets(path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as h5:
        return {k: h5[k][()] for k in h5 if "_dofs" in k or "_nodes" in k}


@serial
def test_resumed_run_writes_the_same_fields(tmp_path):
    """Interrupted after step 2 and resumed: every dof dataset equals an uninterrupted
    run's, bit for bit (serial, direct solver)."""
    from fem_anim.errors import Interrupted
    from fem_anim.simulation.loop import Simulation

    scene = _p2_scene(tmp_path, ["displacement", "energy_density", "velocity"],
                      output={"render": False, "checkpoint_every": 1,
                              "fields": ["velocity"]})
    Simulation(scene).run(tmp_path / "whole", quiet=True)
    cut = Simulation(scene)
    _interrupt_at(cut, 2)
    with pytest.raises(Interrupted):
        cut.run(tmp_path / "cut", quiet=True)
    Simulation(scene).run(tmp_path / "cut", quiet=True, resume=True)
    whole = _dof_datasets(tmp_path / "whole" / "trajectory.h5")
    resumed = _dof_datasets(tmp_path / "cut" / "trajectory.h5")
    assert sorted(whole) == sorted(resumed)
    assert {"displacement_nodes", "velocity_nodes", "displacement_dofs3",
            "velocity_dofs3"} <= set(whole)
    for name, data in whole.items():
        np.testing.assert_array_equal(resumed[name], data, err_msg=name)


@serial
def test_frames_merged_before_a_kill_keep_their_fields(tmp_path):
    """A kill after the merge: the resumed writer takes the kept frames' fields back out of
    ``trajectory.h5``; a resume whose kept frames lack a field (output.fields changed) is an
    error naming the file."""
    from fem_anim.output.trajectory import TrajectoryWriter
    from fem_anim.simulation.loop import Simulation

    sim = Simulation(_p2_scene(tmp_path, ["velocity"]))
    nodes = {name: g.nodes for name, g in sim.dof_gathers.items()}
    n = nodes["velocity"].shape[0]
    rng = np.random.default_rng(1)
    frames = [{name: rng.normal(size=(n, 3)) for name in nodes} for _ in range(3)]
    vertex = sim.domain.points.shape[0]
    cells = sim.domain.cells.shape[0]
    path = tmp_path / "trajectory.xdmf"
    writer = TrajectoryWriter(path, sim.domain, None, nodes)
    for k, dofs in enumerate(frames):
        writer.write(0.1 * k, dofs["displacement"][:vertex], np.zeros(cells), dofs)
    writer.finish()
    again = TrajectoryWriter(path, sim.domain, 2, nodes)
    again.write(0.25, frames[2]["displacement"][:vertex], np.zeros(cells), frames[2])
    again.finish()
    with h5py.File(tmp_path / "trajectory.h5", "r") as h5:
        assert list(h5.attrs["times"]) == [0.0, 0.1, 0.25]
        for k in range(3):
            for name in nodes:
                np.testing.assert_array_equal(h5[f"{name}_dofs{k}"][()], frames[k][name])
        np.testing.assert_array_equal(h5["velocity_nodes"][()], nodes["velocity"])
    with pytest.raises(OSError, match="no pressure field, which output.fields lists now"):
        TrajectoryWriter(path, sim.domain, 2, nodes | {"pressure": nodes["velocity"]})


@serial
@pytest.mark.mpi
def test_two_ranks_write_the_serial_fields_and_handle_work(tmp_path):
    """Under ``mpirun -n 2`` every dof row names the same dof (the same nodes) and holds the
    serial value to 1e-8; each step's handle work agrees likewise."""
    import csv
    import subprocess

    from conftest import clean_environment, fem_anim_command, mpirun_command

    handle = {"name": "handle", "min": [1.0 - 1e-6, -1.0, -1.0],
              "max": [1.0 + 1e-6, 1.0, 1.0], "velocity": [0.0, 0.0, 0.05]}
    scene = bar("p2mpi", element={"degree": 2}, pin=[bar("x")["pin"][0], handle],
                time={"dt": H, "steps": 3, "integrator": "implicit_euler"},
                output={"render": False, "fields": ["velocity"]})
    make_scene(tmp_path, scene)
    outs = {}
    for ranks in (1, 2):
        prefix = [] if ranks == 1 else mpirun_command(2)
        if prefix is None:
            pytest.skip("mpirun not available")
        out = tmp_path / f"out{ranks}"
        r = subprocess.run(prefix + fem_anim_command() + ["run", "-q", "p2mpi.toml", "-o",
                                                          str(out)],
                           cwd=tmp_path, capture_output=True, text=True, timeout=600,
                           env=clean_environment())
        assert r.returncode == 0, r.stderr
        outs[ranks] = out
    a, b = (_dof_datasets(outs[k] / "trajectory.h5") for k in (1, 2))
    assert sorted(a) == sorted(b) and "displacement_dofs3" in a
    for name, data in a.items():
        if name.endswith("_nodes"):
            np.testing.assert_array_equal(b[name], data, err_msg=name)
        else:
            np.testing.assert_allclose(b[name], data, rtol=0,
                                       atol=1e-8 * max(np.abs(data).max(), 1e-30),
                                       err_msg=name)
    works = [[float(r["handle_work"]) for r in csv.DictReader(open(outs[k] / "stats.csv"))]
             for k in (1, 2)]
    assert max(works[0]) > 0.0
    np.testing.assert_allclose(works[1], works[0], rtol=1e-8)


def test_dof_rows_hold_the_field_at_their_nodes(tmp_path):
    """A P2 field interpolated from a known function: row (i, j) holds it at the midpoint of
    input vertices i and j (at vertex i when i == j); scattered back it is the field; a P3
    space, whose dofs sit at thirds of the edges, is refused."""
    from dolfinx import fem

    from fem_anim import compat
    from fem_anim.mesh.bodies import build_scene_mesh
    from fem_anim.output.dof_gather import DofGather

    domain = build_scene_mesh(MPI.COMM_WORLD, _p2_scene(tmp_path, ["velocity"]))
    V = compat.vector_space(domain.mesh, 2)
    u = fem.Function(V)

    def field(x):
        return np.stack([x[0] ** 2, x[1] * x[0], np.sin(3.0 * x[2])])

    u.interpolate(field)
    gather = DofGather(domain, V)
    rows = gather.gather(u.x.array)
    if MPI.COMM_WORLD.rank == 0:
        at = 0.5 * (domain.points[gather.nodes[:, 0]] + domain.points[gather.nodes[:, 1]])
        np.testing.assert_allclose(rows, field(at.T).T, rtol=0, atol=1e-14)
        assert rows.shape[0] == gather.nodes.shape[0] > domain.points.shape[0]
    back = fem.Function(V)
    gather.scatter(rows, back.x.array)
    back.x.scatter_forward()
    np.testing.assert_allclose(back.x.array, u.x.array, rtol=0, atol=1e-14)
    with pytest.raises(ValueError, match="degree 1 or 2"):
        DofGather(domain, compat.vector_space(domain.mesh, 3))
