"""Output a person looks at: frames, GIF, MP4, the energy density field, plots.

Two tiny real runs (module fixtures): the hanging beam, coarse, 4 steps, 64x48 pictures;
and a 2D square in free fall with no pins, whose |u| is the same at every vertex
(1/2 g t^2), so each frame is one colour: with the colour range fixed over the run the
colours differ from frame to frame, and with the camera fixed the square moves down the
picture. Rendering runs in its own process (fem_anim.render.process); these tests read the
pictures back with imageio and imageio-ffmpeg.
"""

from __future__ import annotations

import csv
import json
import subprocess

import imageio.v3 as iio
import imageio_ffmpeg
import meshio
import numpy as np
import pytest
from conftest import clean_environment, fem_anim_command, mpirun_command

from fem_anim.output.products import STAGING_PREFIX
from fem_anim.render.animation import gif_stride
from fem_anim.cli import main
from fem_anim.reference.geometry import cell_volumes, deformation_gradient
from fem_anim.reference.materials import lame_parameters, psi

BEAM = ["--set", "time.steps=4", "--set", "mesh.element_size=0.1",
        "--set", "render.window_size=[64,48]", "--set", "render.fps=10"]
FALL = ["--set", "mesh.dim=2", "--set", "mesh.size=[0.2,0.2]", "--set", "mesh.element_size=0.1",
        "--set", "gravity.acceleration=[0,-9.81]", "--set", "time.dt=0.05",
        "--set", "time.steps=4", "--set", "render.window_size=[96,96]",
        "--set", "render.show_edges=false", "--set", 'render.outputs=["frames"]']


def _fall_scene(tmp_path):
    """The default scene without its pin (a scene cannot remove a [[pin]] by --set)."""
    scene = tmp_path / "fall.toml"
    scene.write_text('name = "fall"\n[gravity]\nacceleration = [0.0, 0.0, -9.81]\n')
    return str(scene)


@pytest.fixture(scope="module")
def beam(tmp_path_factory):
    out = tmp_path_factory.mktemp("render") / "beam"
    assert main(["run", "-o", str(out), "-q", *BEAM]) == 0
    return out


@pytest.fixture(scope="module")
def fall(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fall")
    out = tmp / "out"
    assert main(["run", _fall_scene(tmp), "-o", str(out), "-q", *FALL]) == 0
    return out


def _frames(out):
    return [iio.imread(p) for p in sorted((out / "frames").glob("frame_*.png"))]


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fem-anim: error: "), err
    return err[0]


def test_frames_are_pictures_of_every_frame(beam):
    names = sorted(p.name for p in (beam / "frames").iterdir())
    assert names == [f"frame_{k:04d}.png" for k in range(5)]  # the rest state and 4 steps
    frames = _frames(beam)
    for image in frames:
        assert image.shape == (48, 64, 3)
        assert image.std() > 10 and len(np.unique(image.reshape(-1, 3), axis=0)) > 20
    for a, b in zip(frames, frames[1:]):
        assert np.abs(a.astype(int) - b).sum() > 0  # the beam moves
    np.testing.assert_array_equal(iio.imread(beam / "final.png"), frames[-1])


def test_gif_has_every_frame(beam):
    gif = iio.imread(beam / "animation.gif", index=None)
    assert gif.shape[0] == 5 and gif.shape[1:3] == (48, 64)
    meta = iio.immeta(beam / "animation.gif", index=0)
    assert meta["duration"] == pytest.approx(100)  # ms at render.fps = 10
    assert gif_stride(60) == 2 and gif_stride(50) == 1 and gif_stride(10) == 1


def test_mp4_is_readable(beam):
    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(beam / "animation.mp4"))
    assert frames == 5 and seconds == pytest.approx(0.5, abs=0.01)
    reader = imageio_ffmpeg.read_frames(str(beam / "animation.mp4"))
    meta = next(reader)
    assert tuple(meta["size"]) == (64, 48) and meta["fps"] == pytest.approx(10)
    first = np.frombuffer(next(reader), np.uint8).reshape(48, 64, 3)
    reader.close()
    # lossy H.264 of the first PNG frame: close on average
    assert np.abs(first.astype(float) - _frames(beam)[0]).mean() < 12


def test_plots_beside_the_frames(beam):
    for name in ("energies.png", "newton.png"):
        image = iio.imread(beam / name)
        assert image.ndim == 3 and image.shape[0] > 300 and image.std() > 10


def test_energy_density_equals_numpy_reference(beam):
    """The trajectory's cell field is psi(F) per cell (P1: F constant in a cell), computed
    here in numpy from the saved displacements, and sum_K |K| psi_K is the elastic energy
    stats.csv reports."""
    with meshio.xdmf.TimeSeriesReader(str(beam / "trajectory.xdmf")) as reader:
        points, blocks = reader.read_points_cells()
        frames = [reader.read_data(k) for k in range(reader.num_steps)]
    cells = blocks[0].data
    with open(beam / "stats.csv") as f:
        elastic = [float(row["elastic"]) for row in csv.DictReader(f)]
    mu, lmbda = lame_parameters(1.0e5, 0.3)
    volumes = cell_volumes(points, cells)
    t, point_data, cell_data = frames[-1]
    u = point_data["displacement"]
    field = cell_data["energy_density"][0]
    expected = psi("neohookean", deformation_gradient(points, cells, (points + u).ravel()),
                   mu, lmbda)
    assert np.abs(expected).max() > 10.0  # a deformed state
    np.testing.assert_allclose(field, expected, rtol=1e-10, atol=1e-10 * expected.max())
    assert np.dot(volumes, field) == pytest.approx(elastic[-1], rel=1e-10)
    assert np.abs(frames[0][2]["energy_density"][0]).max() == 0.0  # rest state
    final = meshio.read(beam / "final.vtu")
    np.testing.assert_array_equal(final.cell_data["energy_density"][0], field)


def test_colour_range_and_camera_fixed_over_the_run(fall):
    frames = _frames(fall)
    assert len(frames) == 5
    background = frames[0][0, 0]
    colours, rows = [], []
    for image in frames:
        body = np.any(image != background, axis=2)
        pixels = image[body]
        values, counts = np.unique(pixels, axis=0, return_counts=True)
        colour = values[np.argmax(counts)]  # the square's one colour
        colours.append(colour.astype(int))
        rows.append(np.nonzero(np.all(image == colour, axis=2))[0].mean())
    # |u| grows as t^2 on every vertex: the fixed range gives each frame its own colour
    for a, b in zip(colours, colours[1:]):
        assert np.abs(a - b).sum() > 15, colours
    assert np.all(np.diff(rows[1:]) > 1.0), rows  # falls down the picture: camera fixed
    assert not (fall / "animation.gif").exists() and not (fall / "animation.mp4").exists()


def test_render_again_without_simulating(beam, capsys):
    h5 = (beam / "trajectory.h5").stat().st_mtime_ns
    before = _frames(beam)
    assert main(["render", str(beam), "-q", "--set", "render.color_by=energy_density",
                 "--set", "render.colormap=magma", "--set", "render.background=black"]) == 0
    after = _frames(beam)
    assert len(after) == len(before)
    assert all(np.abs(a.astype(int) - b).sum() > 0 for a, b in zip(before, after))
    assert (beam / "trajectory.h5").stat().st_mtime_ns == h5
    assert json.loads((beam / "scene.json").read_text())["scene"]["name"] == "hanging_beam"
    assert not list(beam.glob(STAGING_PREFIX + "*"))  # the staged pictures were installed


@pytest.mark.parametrize("where, words", [
    ("missing", "does not exist"),
    ("file", "is not a run directory"),
    ("empty", "is not a fem-anim run directory"),
    ("partial", "holds an unfinished run"),
    ("broken", "cannot be read"),
])
def test_render_rejects_what_is_not_a_run(tmp_path, capsys, where, words):
    target = tmp_path / where
    if where == "file":
        target.write_text("x")
    elif where == "empty":
        target.mkdir()
    elif where == "partial":
        (target / ".partial").mkdir(parents=True)
    elif where == "broken":
        target.mkdir()
        for name in ("trajectory.xdmf", "trajectory.h5", "stats.csv"):
            (target / name).write_text("not a trajectory")
    assert main(["render", str(target)]) == 2
    line = _one_error_line(capsys)
    assert str(target) in line and words in line, line


@pytest.mark.parametrize("override, key", [
    ("render.colormap=notamap", "render.colormap"),
    ("render.color_by=stress", "render.color_by"),
    ("render.window_size=[64]", "render.window_size"),
    ("render.fps=-3", "render.fps"),
    ('render.outputs=["avi"]', "render.outputs"),
    ("render.background=nocolour", "render.background"),
    ("render.view=top", "render.view"),
    ("render.focal_point=[0,0,0]", "render.focal_point"),
    ("render.shiny=true", "render.shiny"),
])
def test_bad_render_keys_exit_2(tmp_path, capsys, override, key):
    assert main(["run", "-o", str(tmp_path / "x"), "--set", override]) == 2
    assert key in _one_error_line(capsys)
    assert not (tmp_path / "x").exists()  # validated before anything ran


def test_render_accepts_only_render_keys(beam, capsys):
    assert main(["render", str(beam), "--set", "time.dt=0.1"]) == 2
    assert "only render.* keys" in _one_error_line(capsys)
    assert main(["render", str(beam), "--set", "render.fps=0"]) == 2
    assert "render.fps" in _one_error_line(capsys)


def test_no_pictures_when_rendering_is_off(tmp_path):
    """... and a new run into a directory removes the old run's pictures."""
    out = tmp_path / "quiet"
    assert main(["run", "-o", str(out), "-q", *BEAM, "--set", "time.steps=1",
                 "--set", 'render.outputs=["frames"]']) == 0
    assert (out / "final.png").is_file() and (out / "frames" / "frame_0001.png").is_file()
    assert main(["run", "-o", str(out), "-q", *BEAM, "--set", "output.render=false",
                 "--set", "time.steps=1"]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"trajectory.xdmf", "stats.csv", "final.vtu", "scene.json"} <= names
    assert not names & {"final.png", "frames", "animation.gif", "energies.png"}


@pytest.mark.mpi
def test_energy_density_under_mpi_equals_serial(tmp_path, beam):
    """Cells gathered in input order from 2 ranks: the same field as the serial run."""
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    out = tmp_path / "mpi"
    proc = subprocess.run(mpirun + fem_anim_command() + ["run", "-o", str(out), "-q", *BEAM,
                                                          "--set", "output.render=false"],
                          capture_output=True, text=True, timeout=600, env=clean_environment())
    assert proc.returncode == 0, proc.stderr
    serial = meshio.read(beam / "final.vtu").cell_data["energy_density"][0]
    parallel = meshio.read(out / "final.vtu").cell_data["energy_density"][0]
    np.testing.assert_allclose(parallel, serial, rtol=1e-7, atol=1e-9 * serial.max())


def test_explicit_camera_and_final_only(fall):
    """render.camera_position moves the picture; render.outputs = [] makes final.png only."""
    before = iio.imread(fall / "final.png")
    assert main(["render", str(fall), "-q", "--set", "render.camera_position=[0.1,-2,1]",
                 "--set", "render.view_up=[0,0,1]", "--set", "render.outputs=[]"]) == 0
    after = iio.imread(fall / "final.png")
    assert after.shape == before.shape and np.abs(after.astype(int) - before).sum() > 0
    assert (fall / "energies.png").is_file() and (fall / "frames").is_dir()


@pytest.mark.slow
def test_energy_density_p2_sums_to_the_elastic_energy(tmp_path):
    """P2: psi varies in a cell; its cell means weighted by |K| give the elastic energy."""
    out = tmp_path / "p2"
    assert main(["run", "-o", str(out), "-q", *BEAM, "--set", "element.degree=2",
                 "--set", "time.steps=2", "--set", "output.render=false"]) == 0
    final = meshio.read(out / "final.vtu")
    cells = final.cells_dict["tetra"]
    with open(out / "stats.csv") as f:
        elastic = [float(row["elastic"]) for row in csv.DictReader(f)][-1]
    field = final.cell_data["energy_density"][0]
    assert elastic > 1e-3
    assert np.dot(cell_volumes(final.points, cells), field) == pytest.approx(elastic, rel=1e-10)


def test_plots_mark_retries_and_substeps(tmp_path):
    """stats.csv with a retried, halved step: the plots are drawn from its columns."""
    from fem_anim.output.files import STATS_COLUMNS
    from fem_anim.render.plots import read_stats, write_plots

    rows = [dict.fromkeys(STATS_COLUMNS, 0.0) | {"step": k + 1, "time": t, "dt": dt,
                                                  "retries": r, "newton_its": 3 + r,
                                                  "linear_its": 3 + r, "kinetic": t,
                                                  "gravity": -t, "total_energy": 0.0}
            for k, (t, dt, r) in enumerate([(0.1, 0.1, 0), (0.15, 0.05, 2), (0.2, 0.05, 0),
                                            (0.3, 0.1, 0)])]
    with open(tmp_path / "stats.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=STATS_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    stats = read_stats(tmp_path / "stats.csv")
    np.testing.assert_array_equal(stats["retries"], [0, 2, 0, 0])
    for path in write_plots(tmp_path / "stats.csv", tmp_path):
        assert iio.imread(path).std() > 10
    (tmp_path / "bad.csv").write_text("step,time\n1,x\n")
    with pytest.raises(Exception, match="bad.csv has no column dt"):
        read_stats(tmp_path / "bad.csv")
