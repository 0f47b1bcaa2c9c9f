"""A saved run as pictures: PNG frames, an animated GIF, an MP4 video, ``final.png``.

:func:`render_directory` reads a run directory (``trajectory.xdmf`` + ``.h5`` through
meshio's TimeSeriesReader, ``stats.csv``, the scene from ``scene.json``), fills in the
``[render]`` defaults that depend on the scene (:mod:`~fem_anim.render.render_defaults`),
fixes the colour range over the whole run (the field's range over all frames) and plans
every frame's camera from the bodies' surface in all frames
(:func:`~fem_anim.render.camera.plan_shots`), so neither colours nor framing jump, renders
the frames in worker processes (:mod:`~fem_anim.render.parallel_frames`) after drawing the
plots, and writes

* ``frames/frame_NNNN.png`` (one per trajectory frame, the rest state first),
* ``animation.gif`` (Pillow, one palette; at most 50 frames per second, since GIF delays
  are whole hundredths of a second and viewers slow down shorter ones: faster runs keep
  every k-th frame),
* ``animation.mp4`` (H.264 through the ffmpeg binary of imageio-ffmpeg, x264's
  :data:`X264_PRESET` preset: on rendered frames it takes less time than the default
  preset for a file of about the same size, measured in docs/pictures.md),
* ``final.png`` (the last frame) and the plots of :mod:`fem_anim.render.plots`.

Everything is written into a fresh staging folder inside ``OUTDIR`` and moved into place
at the end (:func:`fem_anim.output.products.staged_products`): a directory holding a file
of one of these names that fem_anim did not write is refused before anything is rendered,
and an interrupted rendering leaves the previous pictures as they were. Runs in
the rendering process only (see :mod:`fem_anim.render.process`), never beside DOLFINx.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fem_anim.errors import FemAnimError
from fem_anim.output.products import staged_products
from fem_anim.output.rundir import read_manifest
from fem_anim.render.camera import plan_shots
from fem_anim.render.frames import body_labels, scalar_bar_reserve, space_dim, stage_of
from fem_anim.render.parallel_frames import FrameJob, frame_images, worker_count
from fem_anim.render.render_defaults import resolve_settings
from fem_anim.render.outer_surface import outer_faces
from fem_anim.render.png_writer import write_png

__all__ = ["RunFrames", "check_run_directory", "read_run", "frame_values", "gif_stride",
           "render_directory", "product_names", "REQUIRED_FILES", "MAX_GIF_FPS", "X264_PRESET"]

#: What a finished run directory holds before it is rendered.
REQUIRED_FILES = ("trajectory.xdmf", "trajectory.h5", "stats.csv")
#: GIF frame delays are hundredths of a second; browsers treat 0.01 s as 0.1 s.
MAX_GIF_FPS = 50.0
#: x264's speed preset for ``animation.mp4`` (the quality is set by ``quality=7``).
X264_PRESET = "veryfast"
#: Default frame rate bounds when ``render.fps`` is not given (real time otherwise).
DEFAULT_FPS_RANGE = (1.0, 60.0)


@dataclass
class RunFrames:
    """A run's trajectory on the input mesh: rank-0 arrays in input order."""

    points: np.ndarray  # (n, d) rest positions
    cells: np.ndarray  # (m, d + 1)
    times: np.ndarray  # (k,)
    displacement: np.ndarray  # (k, n, d)
    energy_density: np.ndarray | None  # (k, m), None for a run written without it


def check_run_directory(path: Path) -> None:
    """Check that ``fem-anim run`` finished in a directory: it holds :data:`REQUIRED_FILES`.

    Args:
        path: The run directory.

    Raises:
        FemAnimError: naming the directory and what is missing.
    """
    path = Path(path)
    if not path.exists():
        raise FemAnimError(f"run directory {path} does not exist")
    if not path.is_dir():
        raise FemAnimError(f"{path} is not a run directory (it is a file)")
    missing = [name for name in REQUIRED_FILES if not (path / name).is_file()]
    if not missing:
        return
    if (path / ".partial").is_dir():
        raise FemAnimError(f"{path} holds an unfinished run (no {missing[0]} yet; its frames "
                           f"are in {path / '.partial'}): finish it with `fem-anim run SCENE "
                           f"--resume {path}`")
    if len(missing) == len(REQUIRED_FILES):
        raise FemAnimError(f"{path} is not a fem-anim run directory (no "
                           f"{', '.join(REQUIRED_FILES)})")
    raise FemAnimError(f"run directory {path} is incomplete: {', '.join(missing)} missing")


def read_run(path: Path) -> RunFrames:
    """Read a run's ``trajectory.xdmf`` with meshio and check every frame is finite.

    Args:
        path: The run directory.

    Returns:
        The rest mesh and every frame's time, displacement and energy density.

    Raises:
        FemAnimError: if the trajectory cannot be read, is empty or holds NaN or inf.
    """
    import meshio

    source = Path(path) / "trajectory.xdmf"
    try:
        with meshio.xdmf.TimeSeriesReader(str(source)) as reader:
            points, blocks = reader.read_points_cells()
            frames = [reader.read_data(k) for k in range(reader.num_steps)]
    except Exception as err:  # meshio raises anything from KeyError to XML parse errors
        raise FemAnimError(f"{source} cannot be read: {type(err).__name__}: {err}") from None
    if not frames or len(blocks) != 1 or blocks[0].type not in ("triangle", "tetra"):
        raise FemAnimError(f"{source} holds no frames of one triangle or tetrahedron mesh")
    d = space_dim(blocks[0].type, Path(path))  # a shell's triangles lie in 3D
    cells = np.asarray(blocks[0].data)
    displacement = np.stack([np.asarray(f[1]["displacement"])[:, :d] for f in frames])
    psi = None
    if all("energy_density" in f[2] for f in frames):
        psi = np.stack([np.ravel(f[2]["energy_density"][0]) for f in frames])
    times = np.array([f[0] for f in frames], dtype=float)
    for name, array in (("time", times), ("displacement", displacement),
                        ("energy_density", psi)):
        if array is not None and not np.all(np.isfinite(array)):
            raise FemAnimError(f"{source}: {name} holds NaN or inf")
    return RunFrames(np.asarray(points)[:, :d], cells, times, displacement, psi)


def frame_values(run: RunFrames, field: str) -> np.ndarray:
    """The colour field of every frame.

    Args:
        run: The trajectory.
        field: ``render.color_by``: ``"displacement"``, ``"energy_density"`` or ``"body"``.

    Returns:
        |u| per vertex (k, n), psi per cell (k, m), or the body number per cell (k, m).

    Raises:
        FemAnimError: if the run has no energy density (written by an older fem-anim).
    """
    if field == "displacement":
        return np.linalg.norm(run.displacement, axis=2)
    if field == "body":
        return np.broadcast_to(body_labels(run.cells), (run.times.size, run.cells.shape[0]))
    if run.energy_density is None:
        raise FemAnimError('render.color_by = "energy_density": this run\'s trajectory has no '
                           "energy_density field; run the scene again")
    return run.energy_density


def gif_stride(fps: float) -> int:
    """How many frames to advance per GIF frame so that it plays at most :data:`MAX_GIF_FPS`.

    Args:
        fps: The animation's frame rate.

    Returns:
        The stride k >= 1 (the GIF keeps every k-th frame).
    """
    return max(1, math.ceil(fps / MAX_GIF_FPS - 1e-9))


def _frame_rate(settings: dict, times: np.ndarray) -> float:
    if settings.get("fps"):
        return float(settings["fps"])
    if times.size < 2:
        return DEFAULT_FPS_RANGE[0]
    real_time = 1.0 / float(np.median(np.diff(times)))
    return float(np.clip(real_time, *DEFAULT_FPS_RANGE))


def _even(image: np.ndarray) -> np.ndarray:
    """Pad to even width and height (H.264's 4:2:0 chroma needs them) by repeating edges."""
    h, w = image.shape[:2]
    return np.pad(image, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")


def _frame_name(k: int, last: int) -> str:
    return f"frame_{k:0{max(4, len(str(last)))}d}.png"


def product_names(run: RunFrames, settings: dict) -> set[str]:
    """The files a rendering of ``run`` writes into its directory.

    Args:
        run: The trajectory.
        settings: The scene's ``[render]`` table (its ``outputs``).

    Returns:
        Relative POSIX paths: ``final.png``, the two plots, and the frames, GIF and MP4
        that ``render.outputs`` asks for.
    """
    outputs = set(settings["outputs"])
    last = run.times.size - 1
    names = {"final.png", "energies.png", "newton.png"}
    if "frames" in outputs:
        names |= {f"frames/{_frame_name(k, last)}" for k in range(last + 1)}
    names |= {f"animation.{kind}" for kind in ("gif", "mp4") if kind in outputs}
    return names


def render_directory(path: Path, settings: dict) -> dict:
    """Render the run in a directory: frames, animations, ``final.png`` and the plots.

    Args:
        path: The finished run directory.
        settings: The scene's ``[render]`` table.

    Returns:
        What was made: ``frames`` rendered, ``seconds_per_frame``, ``fps``, ``gif_frames``.

    Raises:
        FemAnimError: for a directory that is not a finished run, a field it lacks, or
            a file of one of :func:`product_names` in it that fem_anim did not write.
        OSError: if the directory cannot be written (nothing of it is replaced).
    """
    from fem_anim.render.plots import write_plots

    path = Path(path)
    check_run_directory(path)
    run = read_run(path)
    names = product_names(run, settings)
    with staged_products(path, names, replaces=_replaced(path, names)) as staging:
        # the plots in this process, not beside the frames: a process still writing them
        # could outlive an interrupt's clean-up of the staging folder
        write_plots(path / "stats.csv", staging)
        made = _render_frames(run, settings, staging, _run_name(path), _scene(path))
    print(f"rendered {made['frames']} frames ({made['seconds_per_frame']:.3f} s per frame, "
          f"{made['workers']} processes, {made['size']} pixels, {made['fps']:.4g} frames/s) "
          f"into {path}", flush=True)
    return made


def _scene(path: Path) -> dict | None:
    """The run's scene table (from ``scene.json``; ``None`` if it cannot be read)."""
    import json

    try:
        scene = json.loads((path / "scene.json").read_text())["scene"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return scene if isinstance(scene, dict) else None


def _render_frames(run: RunFrames, settings: dict, staging: Path, name: str,
                   scene: dict | None = None) -> dict:
    """Frames, GIF, MP4 and final.png into ``staging``: the cameras planned over the run,
    the frames rendered by :func:`~fem_anim.render.parallel_frames.frame_images`."""
    import imageio_ffmpeg

    settings = resolve_settings(settings, run.cells, scene)
    values = frame_values(run, settings["color_by"])
    clim = (min(0.0, float(values.min())), float(values.max()))
    fps = _frame_rate(settings, run.times)
    stride = gif_stride(fps)
    outputs = set(settings["outputs"])
    last = run.times.size - 1
    order = list(range(last + 1)) if outputs else [last]  # no outputs: final.png only
    if "frames" in outputs:
        (staging / "frames").mkdir()
    d = run.points.shape[1]
    used = np.unique(outer_faces(run.points, run.cells)[0])
    surfaces = [np.hstack([run.points[used] + u[used], np.zeros((used.size, 3 - d))])
                for u in run.displacement]
    obstacles = list((scene or {}).get("obstacle") or [])
    job = FrameJob(run.points, run.cells, settings, clim, stage_of(surfaces), obstacles,
                   run.displacement, values,
                   [f"{name}   frame {k}/{last}   t = {run.times[k]:.3f} s"
                    for k in range(last + 1)],
                   plan_shots(surfaces, settings, d, scalar_bar_reserve(settings)),
                   [staging / "frames" / _frame_name(k, last) if "frames" in outputs
                    else None for k in range(last + 1)])
    workers = worker_count(settings, len(order))
    video, gif = None, []
    start = time.perf_counter()
    try:
        for k, image in zip(order, frame_images(job, order, workers)):
            if "gif" in outputs and k % stride == 0:
                gif.append(image)
            if "mp4" in outputs:
                frame = np.ascontiguousarray(_even(image))
                if video is None:
                    video = _video_writer(staging / "animation.mp4", frame.shape, fps,
                                          imageio_ffmpeg)
                video.send(frame)
        write_png(staging / "final.png", image)
        seconds = (time.perf_counter() - start) / len(order)
    finally:
        if video is not None:
            video.close()
    if gif:
        _write_gif(staging / "animation.gif", gif, 1000.0 * stride / fps)
    return {"frames": len(order), "seconds_per_frame": seconds, "fps": fps,
            "gif_frames": len(gif), "size": f"{image.shape[1]}x{image.shape[0]}",
            "workers": workers}


def _write_gif(path: Path, images: list[np.ndarray], duration_ms: float) -> None:
    """An endlessly looping GIF with one palette for all frames.

    The palette (255 colours, median cut) is taken from the first, middle and last
    frames together: no colour flicker between frames, and 5-10 times faster than
    quantising every frame on its own.
    """
    from PIL import Image

    sample = np.vstack([images[0], images[len(images) // 2], images[-1]])
    palette = Image.fromarray(sample).quantize(colors=255, method=Image.Quantize.MEDIANCUT)
    frames = [Image.fromarray(image).quantize(palette=palette, dither=Image.Dither.NONE)
              for image in images]
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=duration_ms,
                   loop=0)


def _video_writer(path: Path, shape: tuple[int, ...], fps: float, imageio_ffmpeg):
    writer = imageio_ffmpeg.write_frames(
        str(path), (shape[1], shape[0]), fps=fps, codec="libx264", pix_fmt_out="yuv420p",
        quality=7, macro_block_size=2, ffmpeg_log_level="error",
        output_params=["-preset", X264_PRESET])
    writer.send(None)  # start ffmpeg
    return writer


def _run_name(path: Path) -> str:
    import json

    try:
        return json.loads((path / "scene.json").read_text())["scene"]["name"]
    except (OSError, ValueError, KeyError, TypeError):
        return path.resolve().name


def _replaced(path: Path, names: set[str]) -> set[str]:
    """The old pictures a rendering replaces: the manifest's files under the top-level names
    it writes (``frames/`` as a whole, when it makes frames: an older rendering's surplus
    frames go); a user's own files (notes in ``frames/``) are not in the manifest and stay."""
    made = {name.split("/")[0] for name in names}
    return {name for name in read_manifest(path) if name.split("/")[0] in made}
