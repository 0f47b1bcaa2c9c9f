#!/bin/bash
# Side-by-side timing of `fem-anim render` (docs/pictures.md, "Speed"); the Python below says
# how. Run from the repository root: bash docs/picture_scenes/render_bench.sh [REPS | --frame]
exec .venv/bin/python - "$@" <<'PY'
"""`fem-anim render` of the same run directories by three renderers, alternating, on one
machine at one time: BASE (the renderer when issue 29 was filed, commit fb47c9d), MAIN (after
the scene graph was kept between frames, commit 99b7e39) and NOW (this checkout).

Run from the repository root (docs/pictures.md, "Speed"):

    bash docs/picture_scenes/render_bench.sh [REPS]

Everything goes to /tmp/render_bench: a detached worktree and a virtual environment per old
commit (its fem_anim first on the path, this checkout's .venv packages after it), and two runs
simulated once by this checkout with ``output.render = false``: ``pile`` (demos/pile.toml,
60 steps, 61 frames) and ``bin`` (the same pile in a bin, the four walls of
docs/pictures.md appended, 240 steps, 241 frames). Each renderer renders its own copy of a
run (BASE's ``scene.json`` without the render keys it did not know) from /tmp/render_bench,
so no checkout's fem_anim is picked up from the working directory. Prints, per scene and
renderer, every repetition's wall-clock seconds and CPU seconds (user + system of the
command and every process it started: the render process, its threads, ffmpeg), then the
medians and the ratios of the medians to BASE and to MAIN.

With ``--frame`` instead: where a frame's CPU time goes in this checkout, on the pile's 61
frames in this process (CPU time of all its threads; ffmpeg's as a child's): rendering with
the tiles shaded as now, with VTK lighting them, and with no obstacle; the PNG at zlib's
levels 1 and 6 and its mean size; ffmpeg (libx264 at the default preset and at
``veryfast``, ``quality=7``) a frame and the file's size; the GIF per frame it keeps.
"""

from __future__ import annotations

import json
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path.cwd()
WORK = Path("/tmp/render_bench")
REVISIONS = {"BASE": "fb47c9d", "MAIN": "99b7e39"}
#: The [render] keys BASE knew (a newer scene.json's other keys are dropped for it).
BASE_KEYS = {"color_by", "colormap", "view", "camera_position", "focal_point", "view_up",
             "background", "window_size", "fps", "outputs", "show_edges"}
WALLS = [([1.0, 0.0, 0.0], [-0.2, 0.0, 0.0]), ([-1.0, 0.0, 0.0], [0.2, 0.0, 0.0]),
         ([0.0, 1.0, 0.0], [0.0, -0.2, 0.0]), ([0.0, -1.0, 0.0], [0.0, 0.2, 0.0])]
PYTHON = "/usr/bin/python3"  # the interpreter .venv was made with (.ci/setup)


def python_of(name: str) -> str:
    """The interpreter that imports the renderer ``name``."""
    if name == "NOW":
        return str(ROOT / ".venv/bin/python")
    rev = REVISIONS[name]
    tree, venv = WORK / f"tree-{rev}", WORK / f"venv-{rev}"
    if not tree.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(tree), rev], check=True)
    if not venv.exists():
        subprocess.run([PYTHON, "-m", "venv", "--system-site-packages", "--without-pip",
                        str(venv)], check=True)
        site = next(venv.glob("lib/python3*/site-packages"))
        ours = next((ROOT / ".venv").glob("lib/python3*/site-packages"))
        (site / "000base.pth").write_text(f"{tree}\n{ours}\n")
    return str(venv / "bin/python")


def simulate(name: str, steps: int, walls: bool) -> Path:
    """A run directory of the pile, simulated once by this checkout."""
    out = WORK / name
    if (out / "trajectory.h5").exists():
        return out
    scene = (ROOT / "demos/pile.toml").read_text()
    for normal, point in WALLS if walls else []:
        scene += (f'\n[[obstacle]]\ntype = "plane"\nnormal = {normal}\npoint = {point}\n'
                  "dhat = 0.002\nstiffness = 1.0e5\nfriction = 0.3\nepsv = 0.01\n")
    toml = WORK / f"{name}.toml"
    toml.write_text(scene)
    subprocess.run([str(ROOT / ".venv/bin/fem-anim"), "run", str(toml), "-o", str(out), "-q",
                    "--set", "output.render=false", "--set", f"time.steps={steps}"],
                   check=True, cwd=WORK)
    return out


def copy_for(run: Path, name: str) -> Path:
    target = WORK / f"{run.name}-{name}"
    shutil.rmtree(target, ignore_errors=True)
    shutil.copytree(run, target)
    if name == "BASE":
        path = target / "scene.json"
        data = json.loads(path.read_text())
        render = data["scene"].get("render", {})
        data["scene"]["render"] = {k: v for k, v in render.items() if k in BASE_KEYS}
        path.write_text(json.dumps(data))
    return target


def timed(python: str, directory: Path) -> tuple[float, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([python, "-m", "fem_anim", "render", str(directory), "-q"], check=True,
                   cwd=WORK)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def frame_costs(run: Path) -> None:
    """Print the CPU milliseconds a frame of ``run`` takes in each stage (see above)."""
    import os

    import imageio_ffmpeg
    import numpy as np

    from fem_anim.render import animation, png_writer
    from fem_anim.render.camera import plan_shots
    from fem_anim.render.frames import FrameRenderer, scalar_bar_reserve, stage_of
    from fem_anim.render.outer_surface import outer_faces
    from fem_anim.render.render_defaults import resolve_settings

    frames = animation.read_run(run)
    scene = animation._scene(run)
    settings = resolve_settings(scene.get("render", {}), frames.cells, scene)
    values = animation.frame_values(frames, settings["color_by"])
    used = np.unique(outer_faces(frames.points, frames.cells)[0])
    surfaces = [frames.points[used] + u[used] for u in frames.displacement]
    shots = plan_shots(surfaces, settings, 3, scalar_bar_reserve(settings))
    n = len(shots)
    images = []
    for label, obstacles, shaded in (("tiles shaded (now)", scene.get("obstacle", []), True),
                                     ("tiles lit by VTK", scene.get("obstacle", []), False),
                                     ("no obstacle", [], True)):
        renderer = FrameRenderer(frames.points, frames.cells, settings, (0.0, 1.0),
                                 stage_of(surfaces), obstacles, shaded_tiles=shaded)
        renderer.render(frames.displacement[0], values[0], "", shots[0])  # shaders built
        start = time.process_time()
        shown = [renderer.render(frames.displacement[k], values[k], f"frame {k}", shots[k])
                 for k in range(n)]
        print(f"render, {label}: {1e3 * (time.process_time() - start) / n:.1f} ms", flush=True)
        images = images or shown
        renderer.close()
    for level in (1, 6):
        png_writer.ZLIB_LEVEL = level
        start = time.process_time()
        size = sum(len(png_writer.encode_png(image)) for image in images)
        print(f"PNG, zlib level {level}: {1e3 * (time.process_time() - start) / n:.1f} ms, "
              f"{size / n / 1e3:.0f} kB", flush=True)
    for preset in (None, "veryfast"):
        path = WORK / "preset.mp4"
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.process_time()
        writer = imageio_ffmpeg.write_frames(
            str(path), (images[0].shape[1], images[0].shape[0]), fps=60, codec="libx264",
            pix_fmt_out="yuv420p", quality=7, macro_block_size=2, ffmpeg_log_level="error",
            output_params=["-preset", preset] if preset else [])
        writer.send(None)
        for image in images:
            writer.send(np.ascontiguousarray(image))
        writer.close()
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
               + time.process_time() - start)
        print(f"MP4, x264 preset {preset or 'default (medium)'}: {1e3 * cpu / n:.1f} ms, "
              f"{os.path.getsize(path) / 1e3:.0f} kB", flush=True)
    kept = images[::animation.gif_stride(60.0)]
    start = time.process_time()
    animation._write_gif(WORK / "frame_costs.gif", kept, 1000.0 / 30)
    print(f"GIF: {1e3 * (time.process_time() - start) / len(kept):.1f} ms a kept frame "
          f"({len(kept)} of {n})", flush=True)


def main() -> None:
    if sys.argv[1:] == ["--frame"]:
        WORK.mkdir(exist_ok=True)
        frame_costs(simulate("pile", 60, False))
        return
    reps = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    WORK.mkdir(exist_ok=True)
    names = ["BASE", "MAIN", "NOW"]
    pythons = {name: python_of(name) for name in names}
    runs = {"pile": simulate("pile", 60, False), "bin": simulate("bin", 240, True)}
    print("load average at start:", open("/proc/loadavg").read().split()[:3], flush=True)
    for scene, run in runs.items():
        dirs = {name: copy_for(run, name) for name in names}
        times: dict[str, list[tuple[float, float]]] = {name: [] for name in names}
        for rep in range(reps):
            for name in names:
                times[name].append(timed(pythons[name], dirs[name]))
                wall, cpu = times[name][-1]
                print(f"{scene} {name} rep {rep}: wall {wall:.2f} s, cpu {cpu:.2f} s", flush=True)
        median = {name: (statistics.median(w for w, _ in t), statistics.median(c for _, c in t))
                  for name, t in times.items()}
        for name in names:
            wall, cpu = median[name]
            print(f"{scene} {name} median: wall {wall:.2f} s, cpu {cpu:.2f} s; "
                  f"BASE/{name}: wall {median['BASE'][0] / wall:.2f}x, "
                  f"cpu {median['BASE'][1] / cpu:.2f}x; MAIN/{name}: wall "
                  f"{median['MAIN'][0] / wall:.2f}x, cpu {median['MAIN'][1] / cpu:.2f}x",
                  flush=True)
    print("load average at end:", open("/proc/loadavg").read().split()[:3], flush=True)


main()
PY
