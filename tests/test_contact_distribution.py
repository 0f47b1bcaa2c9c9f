"""IPC contact distributed over ranks (:mod:`fem_anim.contact.distribution`).

Issue 33, point 4: each rank handles the contact of the surface it owns plus a halo, no rank
gathers the whole surface, and the results equal serial to 1e-8. The MPI case runs
``tests/mpi/mpi_contact_halo_check.py`` on 1 and on 2 ranks (two pairs of bars thrown
together, with friction) and compares the trajectory, the barrier energy, gradient, Hessian
action, CCD bounds (one inside the halo, one wider than it), pair count and minimum
distance, at a state in contact and after a move past the halo's margin (to 1e-8: the
trajectories differ by round-off), and at one state (the final one rounded to 0.1 um: the same
bits on 1 and 2 ranks) with pairs across the ranks (to 1e-10). The serial cases
check the pieces of the distribution on one rank.
"""

from __future__ import annotations

import subprocess
import sys

import ipctk
import numpy as np
import pytest
from mpi4py import MPI

from conftest import ROOT, clean_environment, mpirun_command
from fem_anim.contact.distribution import VertexExchange, _label_triangles

SCRIPT = ROOT / "tests" / "mpi" / "mpi_contact_halo_check.py"
#: Serial against 2 ranks: the same sums in another order (measured <= 8e-12 relative on
#: the gradient, whose barrier terms amplify the trajectory's 1e-14 differences).
RTOL = 1e-8


def test_label_triangles_give_one_component_per_label():
    """ipctk's connected-components filter on the label triangles: pairs of one label
    may not collide, pairs of two labels may (the ``self = false`` filter on a halo,
    whose pieces of one body need not be connected)."""
    labels = np.array([4, 1, 4, 4, 1, 7, 4, 4])
    tris = _label_triangles(labels)
    V = np.random.default_rng(0).random((labels.size, 3))
    mesh = ipctk.CollisionMesh(V, np.empty((0, 2), np.int32), np.empty((0, 3), np.int32))
    mesh.can_collide = ipctk.make_connected_components_filter(tris)
    for i in range(labels.size):
        for j in range(labels.size):
            if i != j:
                assert mesh.can_collide(i, j) == (labels[i] != labels[j]), (i, j)


def test_vertex_exchange_on_one_rank_fetches_and_sums_back():
    comm = MPI.COMM_SELF
    ex = VertexExchange(comm, np.array([10]), 0, np.array([1, 4, 7]))
    owned = np.arange(30.0).reshape(10, 3)
    assert np.array_equal(ex.fetch(owned), owned[[1, 4, 7]])
    back = np.zeros((10, 3))
    ex.add_back(np.ones((3, 3)), back)
    assert back.sum() == 9 and np.all(back[[1, 4, 7]] == 1)


@pytest.mark.mpi
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches mpirun itself")
def test_distributed_contact_equals_serial(tmp_path):
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    results = {}
    for ranks, prefix in ((1, []), (2, mpirun)):
        out = tmp_path / f"n{ranks}.npz"
        r = subprocess.run([*prefix, sys.executable, str(SCRIPT), str(out)],
                           capture_output=True, text=True, timeout=900,
                           env=clean_environment(), cwd=ROOT)
        assert r.returncode == 0, r.stdout + r.stderr
        results[ranks] = dict(np.load(out))
    one, two = results[1], results[2]
    # the halo is part of the surface, not all of it, and a move past its margin rebuilt it
    assert two["local_faces"].max() < two["surface_faces"] == one["local_faces"][0]
    assert two["rebuilt"] == 1 and one["rebuilt"] == 0  # one rank's mesh: the whole surface
    assert one["final_pairs"] > 100 and one["moved_pairs"] > 10
    for key, value in one.items():
        if key in ("local_faces", "rebuilt", "final_local_bodies", "final_own_bodies") or \
                key.startswith("set_"):
            continue
        other = two[key]
        scale = np.max(np.abs(value)) if np.all(np.isfinite(value)) else 1.0
        assert np.shape(value) == np.shape(other), key
        if np.all(np.isfinite(value)):
            assert np.max(np.abs(value - other)) <= RTOL * scale, key
        else:
            assert np.array_equal(value, other), key
    # the CCD bounds bind (a bound of 1 would not test the sweep)
    assert one["final_wide_step_bound"] < 1 and one["moved_wide_step_bound"] < 1
    # at one state (the final one rounded to 0.1 um: the same bits on 1 and 2 ranks), with
    # pairs between bars 0 and 1 (on two ranks where the partitioner splits them, as
    # DOLFINx 0.5's does: each pair owned by the rank of its lowest vertex, its rows partly
    # sent to the other): the barrier's energy, gradient and Hessian action equal serial to
    # 1e-10 (only the order of sums differs)
    assert one["set_pairs"] > 100
    assert two["set_owned_pairs"].sum() == one["set_pairs"] == two["set_pairs"]
    for key in ("set_energy", "set_gradient", "set_Hz0", "set_Hz1", "set_min_distance"):
        scale = np.max(np.abs(one[key]))
        assert scale > 0 and np.max(np.abs(one[key] - two[key])) <= 1e-10 * scale, key
    assert one["set_step_bound"] == two["set_step_bound"] < 1


@pytest.mark.mpi
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches mpirun itself")
def test_local_meshes_hold_their_share_and_a_halo(tmp_path):
    """Each rank's local mesh is its facets plus the remote facets near them that can serve
    one of its pairs: bars 2 and 3 (0.45 m and more from everything) stay out of every
    other rank's mesh, rank 0 holds the bar touching one of its own if another rank owns
    it, and the highest rank, whose vertices no lower rank's facet touches (whole bodies
    per rank), holds no remote facet at all (a facet whose vertices all belong to lower
    ranks serves no pair it owns)."""
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    out = tmp_path / "n2.npz"
    r = subprocess.run([*mpirun, sys.executable, str(SCRIPT), str(out)], capture_output=True,
                       text=True, timeout=900, env=clean_environment(), cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    two = dict(np.load(out))
    local, own = two["final_local_bodies"], two["final_own_bodies"]  # (ranks, bodies)
    per_body = own.sum(axis=0)
    assert np.all(np.sort(own, axis=0)[-1] == per_body)  # each body on one rank, whole
    assert np.all(local >= own) and own[:, 0].sum() > 0
    for body in (2, 3):  # the far bars: only their own rank holds them
        assert np.array_equal(local[:, body], own[:, body]), (body, local, own)
    # the highest rank holds only its own bars; rank 0 holds the other of the touching bars
    # 0 and 1 when the partitioner put them on two ranks (DOLFINx 0.5 does), else only its own
    assert np.array_equal(local[-1], own[-1]), (local, own)
    for body, partner in ((0, 1), (1, 0)):
        if own[0, partner] and not own[0, body]:
            assert local[0, body] > 0, (local, own)
        else:
            assert local[0, body] == own[0, body], (local, own)
