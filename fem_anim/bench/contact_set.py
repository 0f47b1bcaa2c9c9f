"""``fem-anim bench --contact``: the classic contact set, fem_anim beside the plain IPC step.

    fem-anim bench --contact [--size full|small|reduced] [--only NAME,...] [--steps N]
                             [--out DIR] [--no-pictures]
    (or python -m fem_anim.bench.contact_set ...)

Three scenes (:func:`scene_text`), each run by fem_anim (serial, the scene's defaults, its
adaptive substeps with retries) and, back to back in the same process on the same
tetrahedra (the arrays fem_anim's mesh was built from), by the plain ipctk + scipy IPC step
of :mod:`fem_anim.bench.ipc_baseline`:

* ``stack``: a stack of boxes (10 at full size) standing on the ground for 5 s, friction 0.3;
* ``pile``: bodies (20 at full size, boxes and balls) dropped into a bin of five planes;
* ``twist``: a bar whose end turns four turns while moving inwards, so it buckles and
  touches itself (self-contact).

Implicit Euler and the lumped mass for both, the same neo-Hookean material, obstacles,
d-hat and friction (IPC section 5). Per run: s/step (wall time per frame, discarded tries
included), Newton iterations per step, the share of the wall time spent in ipctk, retries
(count and wall time: a frame's wall time minus its accepted substeps' own), and the ratio
of fem_anim's s/step to the baseline's. Physics check: each body's centre-of-mass height over
the frames (the largest difference between the two runs), and crossed frames (ipctk's
``has_intersections`` on the surface rebuilt from the tetrahedra,
:func:`fem_anim.contact.intersection.crossed_frames`) for both. Writes into ``--out``
(default ``demos/results/contact_set``): per-step CSVs of each run (every number of the
table is recomputed from them by :func:`summarise`), every frame of both runs
(``NAME_frames.npz``) and the bodies' centre-of-mass heights from them
(``NAME_com_heights.csv``), ``contact_set.json``, the Markdown
table ``contact_set.md`` and a small picture of each scene's last frame per run. A run of
some scenes (``--only``) keeps the other scenes' entries of the same size already in
``contact_set.json`` (each with the command and machine line it was measured with).
"""

from __future__ import annotations

import csv
import io
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from fem_anim.errors import FemAnimError
from fem_anim.output.products import check_may_write, write_product

__all__ = ["SCENES", "SIZES", "scene_text", "run_scene", "summarise", "physics_check",
           "main", "COM_TOLERANCE"]

SCENES = ("stack", "pile", "twist")
#: Per size: scene -> (bodies, element size (m), frames). ``full`` is the set as specified;
#: ``small`` the same bodies and durations (the pile 1 s) on coarser meshes, for a loaded
#: machine; ``reduced`` the test's (few bodies, coarse, few frames).
SIZES = {
    "full": {"stack": (10, 0.025, 500), "pile": (20, 0.02, 200), "twist": (1, 0.01, 200)},
    "small": {"stack": (10, 0.05, 500), "pile": (20, 0.03, 100), "twist": (1, 0.02, 200)},
    "reduced": {"stack": (3, 0.05, 8), "pile": (4, 0.03, 8), "twist": (1, 0.03, 8)},
}
#: The largest centre-of-mass height difference (m) between the two runs called agreement.
COM_TOLERANCE = 2.0e-3

DT = 0.01
DHAT = 1.0e-3


def _body(name, offset, mesh, E, rho=1000.0, nu=0.3):
    return (f'[[body]]\nname = "{name}"\noffset = {list(map(float, offset))}\n'
            f"mesh = {mesh}\nmaterial = {{ model = \"neohookean\", youngs_modulus = {E}, "
            f'poisson_ratio = {nu}, density = {rho}, mass = "lumped" }}\n')


def _plane(name, normal, point, stiffness, friction):
    return (f'[[obstacle]]\nname = "{name}"\ntype = "plane"\nnormal = {normal}\n'
            f"point = {point}\ndhat = {DHAT}\nstiffness = {stiffness}\n"
            f"friction = {friction}\nepsv = 0.01\n")


def scene_text(name: str, size: str = "full", steps: int | None = None) -> str:
    """The TOML of a benchmark scene at a size of :data:`SIZES`.

    Args:
        name: One of :data:`SCENES`.
        size: A key of :data:`SIZES`.
        steps: Frames (default: the size's).
    """
    count, h, frames = SIZES[size][name]
    frames = steps or frames
    head = (f'name = "bench_{name}"\n[time]\nintegrator = "implicit_euler"\ndt = {DT}\n'
            f"steps = {frames}\n"
            f"[contact]\ndhat = {DHAT}\nstiffness = \"adaptive\"\n"
            f"friction = {0.3 if name != 'twist' else 0.0}\nepsv = 0.01\n"
            "[output]\nrender = false\n")
    if name == "stack":
        text = head + "[gravity]\nacceleration = [0.0, 0.0, -9.81]\n"
        text += _plane("ground", [0.0, 0.0, 1.0], [0.0, 0.0, 0.0], 1e8, 0.3)
        box = f'{{ shape = "box", size = [0.1, 0.1, 0.1], element_size = {h} }}'
        # boxes 2 d-hat apart, one above the other, of a stiff plastic (E = 100 MPa): a
        # column of the boxes' section buckles under its own weight below
        # E = rho g A L^3 / (7.84 I) ~ 1.5 MPa at L = 1 m (Greenhill), as a softer stack does
        for k in range(count):
            text += _body(f"box{k}", [-0.05, -0.05, 2 * DHAT + k * (0.1 + 2 * DHAT)], box,
                          1e8)
        return text
    if name == "pile":
        text = head + "[gravity]\nacceleration = [0.0, 0.0, -9.81]\n"
        half = 0.1
        for label, normal, point in (("ground", [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]),
                                     ("wall_x0", [1.0, 0.0, 0.0], [-half, 0.0, 0.0]),
                                     ("wall_x1", [-1.0, 0.0, 0.0], [half, 0.0, 0.0]),
                                     ("wall_y0", [0.0, 1.0, 0.0], [0.0, -half, 0.0]),
                                     ("wall_y1", [0.0, -1.0, 0.0], [0.0, half, 0.0])):
            text += _plane(label, normal, point, 1e5, 0.3)
        box = f'{{ shape = "box", size = [0.06, 0.06, 0.06], element_size = {h} }}'
        ball = f'{{ shape = "sphere", radius = 0.03, element_size = {h} }}'
        for k in range(count):  # layers of 2 x 2, boxes and balls alternating
            i, j, layer = k % 2, (k // 2) % 2, k // 4
            cx, cy, cz = -0.045 + 0.09 * i, -0.045 + 0.09 * j, 0.04 + 0.075 * layer
            if (i + j + layer) % 2 == 0:
                text += _body(f"box{k}", [cx - 0.03, cy - 0.03, cz - 0.03], box, 1e5)
            else:
                text += _body(f"ball{k}", [cx, cy, cz], ball, 1e5)
        return text
    if name == "twist":
        length = 0.5
        text = head
        text += _body("bar", [0.0, 0.0, 0.0],
                      f'{{ shape = "box", size = [{length}, 0.03, 0.03], element_size = {h} }}',
                      1e5)
        # the left end holds; the right end turns 4 turns in 2 s about the bar's axis while
        # moving 0.2 m inwards, so the bar buckles and winds onto itself
        text += ('[[body.pin]]\nname = "left"\nmin = [-1e-6, -1.0, -1.0]\n'
                 'max = [1e-6, 1.0, 1.0]\n')
        text += (f'[[body.pin]]\nname = "right"\nmin = [{length - 1e-6}, -1.0, -1.0]\n'
                 f"max = [{length + 1e-6}, 1.0, 1.0]\nangular_velocity = {4 * np.pi}\n"
                 f"axis = [1.0, 0.0, 0.0]\ncenter = [{length}, 0.015, 0.015]\n"
                 "velocity = [-0.1, 0.0, 0.0]\nuntil = 2.0\n")
        return text
    raise FemAnimError(f"unknown bench scene {name!r}; choose from {', '.join(SCENES)}")


# -- the two runs ---------------------------------------------------------------------------
def _fem_anim_run(scene, frames: int):
    """fem_anim's run: per-substep rows and the vertex displacement of each frame."""
    from mpi4py import MPI

    from fem_anim.simulation.adaptive import AdaptiveStepper
    from fem_anim.simulation.loop import Simulation

    sim = Simulation(scene, MPI.COMM_SELF)
    dt = scene["time"]["dt"]
    stepper = AdaptiveStepper(sim, dt, scene["time"])
    state = sim.initial_state()
    rows, shots = [], [sim.gather.gather(state.u)]
    for k in range(frames):
        start = time.perf_counter()
        for state, row in stepper.advance(state, (k + 1) * dt):
            now = time.perf_counter()
            rows.append({"frame": k + 1, "time": row["time"], "dt": row["dt"],
                         "wall_s": now - start, "step_wall_s": row["step_wall_s"],
                         "newton_its": row["newton_its"], "ipc_s": row["contact_s"],
                         "retries": row["retries"], "pairs": row["contact_pairs"]})
            start = now
        shots.append(sim.gather.gather(state.u))
    return sim.domain, rows, shots


def _baseline(scene, domain):
    """The baseline on fem_anim's tetrahedra, with the scene's bodies, obstacles and pins."""
    from fem_anim.bench.ipc_baseline import IPCBaseline
    from fem_anim.problem.handles import PinMotion
    from fem_anim.reference.materials import lame_parameters

    points, cells = domain.points, domain.cells
    body = domain.cell_markers - 1
    bodies = scene["body"]
    E = np.array([b["material"]["youngs_modulus"] for b in bodies])[body]
    nu = np.array([b["material"]["poisson_ratio"] for b in bodies])[body]
    rho = np.array([b["material"]["density"] for b in bodies])[body]
    mu, lmbda = lame_parameters(E, nu)
    pins = []
    for k, b in enumerate(bodies):
        vertices_k = np.unique(cells[body == k])
        for pin in b.get("pin", []):
            lo, hi = np.asarray(pin["min"]), np.asarray(pin["max"])
            X = points[vertices_k]
            inside = vertices_k[np.all((X >= lo) & (X <= hi), axis=1)]
            moving = pin["velocity"] is not None or pin["angular_velocity"] != 0
            motion = PinMotion.from_scene(pin, inside, points[inside]) if moving else None
            pins.append((inside, motion))
    gravity = scene["gravity"]["acceleration"] if "gravity" in scene.data else [0.0] * 3
    obstacles = scene["obstacle"] if "obstacle" in scene.data else []
    return IPCBaseline(points, cells, mu, lmbda, rho, gravity, obstacles, scene["contact"],
                       pins)


def _baseline_run(scene, domain, frames: int, velocity=None):
    """The baseline's frames from rest, or from the vertex velocities ``velocity`` (n, 3)
    (m/s; fem_anim's initial state, for a scene with ``[body.initial]``)."""
    sim = _baseline(scene, domain)
    if velocity is not None:
        sim.v = np.asarray(velocity, float).ravel().copy()
    dt = scene["time"]["dt"]
    rows, shots = [], [np.zeros_like(domain.points)]
    for k in range(frames):
        cpu = time.process_time()
        s = sim.step(dt)
        cpu = time.process_time() - cpu
        rows.append({"frame": k + 1, "time": sim.t, "dt": dt, "wall_s": s.wall_s,
                     "cpu_s": cpu,
                     "step_wall_s": s.wall_s, "newton_its": s.newton_its, "ipc_s": s.ipc_s,
                     "retries": 0, "pairs": s.pairs, "converged": int(s.converged)})
        shots.append(sim.x.reshape(-1, 3) - domain.points)
    return rows, shots


def summarise(rows: list[dict], frames: int) -> dict:
    """The table's numbers of one run from its per-substep rows (as read back from its CSV).

    Returns:
        ``s_per_step``: wall seconds per frame (failed tries included), ``newton_per_step``:
        Newton iterations of the accepted substeps per frame, ``ipc_share``: time in ipctk
        over the wall time, ``retries`` and ``retry_s``: the failed tries and their wall time
        (wall time minus the accepted substeps' own), ``substeps``.
    """
    wall = sum(float(r["wall_s"]) for r in rows)
    own = sum(float(r["step_wall_s"]) for r in rows)
    return {"s_per_step": wall / frames,
            "newton_per_step": sum(int(r["newton_its"]) for r in rows) / frames,
            "ipc_share": sum(float(r["ipc_s"]) for r in rows) / wall,
            "retries": sum(int(r["retries"]) for r in rows), "retry_s": wall - own,
            "substeps": len(rows), "wall_s": wall}


def _com_heights(points, cells, body, shots) -> np.ndarray:
    """Each body's centre-of-mass height (volume-weighted) per frame, (frames, bodies)."""
    from fem_anim.reference.geometry import cell_volumes

    vol = cell_volumes(points, cells)
    nb = int(body.max()) + 1
    weights = np.zeros((points.shape[0], nb))
    np.add.at(weights, (cells.ravel(), np.repeat(body, 4)), np.repeat(vol / 4.0, 4))
    weights /= weights.sum(axis=0)
    return np.array([(points[:, 2] + u[:, 2]) @ weights for u in shots])


def physics_check(com_fa: np.ndarray, com_bl: np.ndarray, dt: float = DT) -> dict:
    """The two runs' centre-of-mass heights compared, (frames, bodies) each.

    Returns:
        ``com_height_max_diff_m``: the largest difference of a body's height over all
        frames; ``com_height_final_diff_m``: at the last frame; ``agree_until_s``: the time of
        the last frame up to which every body's heights agree within :data:`COM_TOLERANCE`
        (a pile is chaotic: two correct codes part ways after the first impacts);
        ``mean_height_final_diff_m``: the difference of the bodies' mean height at the end.
    """
    diff = np.max(np.abs(com_fa - com_bl), axis=1)
    apart = np.flatnonzero(diff > COM_TOLERANCE)
    last = (apart[0] - 1) if apart.size else diff.size - 1
    return {"com_height_max_diff_m": float(diff.max()),
            "com_height_final_diff_m": float(diff[-1]),
            "agree_until_s": float(last * dt),
            "mean_height_final_diff_m": float(abs(com_fa[-1].mean() - com_bl[-1].mean()))}


def write_com_heights(out: Path, name: str) -> None:
    """``NAME_com_heights.csv`` from ``NAME_frames.npz``: every body's centre-of-mass height
    (m) per frame in both runs, the small file the physics columns are recomputed from
    (the frames themselves are megabytes)."""
    data = np.load(out / f"{name}_frames.npz")
    com = {w: _com_heights(data["points"], data["cells"], data["body"], data[w])
           for w in ("fem_anim", "baseline")}
    rows = [{"frame": k, "time": k * DT, "body": b, "fem_anim_m": com["fem_anim"][k, b],
             "baseline_m": com["baseline"][k, b]}
            for k in range(com["fem_anim"].shape[0]) for b in range(com["fem_anim"].shape[1])]
    write_product(out / f"{name}_com_heights.csv", _csv(rows))


def _csv(rows: list[dict]) -> bytes:
    table = io.StringIO(newline="")
    writer = csv.DictWriter(table, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    return table.getvalue().encode()


def _picture(path: Path, points, cells, body, u, title: str) -> None:
    """A small PNG of the surface at displacement u, a colour per body (off screen)."""
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    from fem_anim.contact.intersection import boundary_triangles

    faces = boundary_triangles(cells)
    surf = pv.PolyData(points + u, np.hstack([np.full((len(faces), 1), 3), faces]).ravel())
    vertex_body = np.zeros(points.shape[0])
    vertex_body[cells.ravel()] = np.repeat(body % 10, 4)
    plotter = pv.Plotter(off_screen=True, window_size=(320, 320))
    plotter.add_mesh(surf, scalars=vertex_body, cmap="tab10", clim=[0, 9],
                     show_scalar_bar=False, show_edges=True, edge_color="#333333",
                     line_width=0.5)
    plotter.add_text(title, font_size=9)
    plotter.view_isometric()
    png = plotter.screenshot(return_img=True)
    plotter.close()
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(png).save(buffer, format="PNG", optimize=True)
    write_product(path, buffer.getvalue())


def run_scene(name: str, size: str, out: Path, steps: int | None = None,
              pictures: bool = True, log=print) -> dict:
    """Run one scene with fem_anim and the baseline back to back; write its files.

    Returns:
        The scene's entry of ``contact_set.json``.
    """
    previous = _blas_threads(1)
    try:
        return _run_scene(name, size, out, steps, pictures, log)
    finally:
        _blas_threads(previous)


def _blas_threads(n: int) -> int:
    """Set OpenBLAS's thread count (numpy's and PETSc's BLAS); return the previous one.

    Both runs are serial: OpenBLAS's threads on numpy's batched small matrices (the
    baseline's 9 x 9 eigenproblems) cost ten times their work on a shared machine.
    """
    import ctypes

    try:
        lib = ctypes.CDLL("libopenblas.so.0")
    except OSError:
        return n
    before = int(lib.openblas_get_num_threads())
    lib.openblas_set_num_threads(int(n))
    return before


def _run_scene(name, size, out, steps, pictures, log) -> dict:
    from fem_anim.contact.intersection import crossed_frames
    from fem_anim.scene.loading import load_scene

    text = scene_text(name, size, steps)
    path = out / f"{name}.toml"
    write_product(path, text.encode())
    scene = load_scene(path)
    frames = scene["time"]["steps"]
    domain, fa_rows, fa_shots = _fem_anim_run(scene, frames)
    log(f"  {name}: fem_anim done ({len(fa_rows)} substeps)")
    bl_rows, bl_shots = _baseline_run(scene, domain, frames)
    log(f"  {name}: baseline done")
    write_product(out / f"{name}_fem_anim.csv", _csv(fa_rows))
    write_product(out / f"{name}_baseline.csv", _csv(bl_rows))
    points, cells, body = domain.points, domain.cells, domain.cell_markers - 1
    com_fa = _com_heights(points, cells, body, fa_shots)
    com_bl = _com_heights(points, cells, body, bl_shots)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, points=points, cells=cells, body=body,
                        fem_anim=np.array(fa_shots), baseline=np.array(bl_shots))
    write_product(out / f"{name}_frames.npz", buffer.getvalue())
    write_com_heights(out, name)
    if pictures:
        _picture(out / f"{name}_fem_anim.png", points, cells, body, fa_shots[-1],
                 f"{name}: fem_anim, t = {frames * DT:.2f} s")
        _picture(out / f"{name}_baseline.png", points, cells, body, bl_shots[-1],
                 f"{name}: ipctk+scipy, t = {frames * DT:.2f} s")
    entry = {"scene": name, "size": size, "frames": frames, "tets": int(cells.shape[0]),
             "bodies": int(body.max()) + 1,
             "fem_anim": {**summarise(fa_rows, frames),
                          "crossed_frames": len(crossed_frames(points, cells, fa_shots))},
             "baseline": {**summarise(bl_rows, frames),
                          "crossed_frames": len(crossed_frames(points, cells, bl_shots)),
                          "unconverged_steps": sum(1 - r["converged"] for r in bl_rows)},
             **physics_check(com_fa, com_bl),
             "max_pairs": {"fem_anim": max(int(r["pairs"]) for r in fa_rows),
                           "baseline": max(int(r["pairs"]) for r in bl_rows)}}
    entry["ratio"] = entry["fem_anim"]["s_per_step"] / entry["baseline"]["s_per_step"]
    log(f"  {name}: " + json.dumps(entry))
    return entry


def table(entries: list[dict]) -> str:
    """The Markdown table of :func:`run_scene`'s entries."""
    from fem_anim.bench.report import md_table

    rows = []
    for e in entries:
        for who, label in (("fem_anim", "fem_anim"), ("baseline", "ipctk+scipy")):
            r = e[who]
            rows.append([e["scene"], e["tets"], e["frames"], label, r["s_per_step"],
                         r["newton_per_step"], f"{100 * r['ipc_share']:.0f} %",
                         f"{r['retries']} ({r['retry_s']:.1f} s)", r["crossed_frames"],
                         f"{e['ratio']:.2f}" if who == "fem_anim" else "1",
                         f"{1e3 * e['com_height_max_diff_m']:.2f}"
                         if who == "fem_anim" else "",
                         f"{e['agree_until_s']:.2f}" if who == "fem_anim" else "",
                         f"{1e3 * e['mean_height_final_diff_m']:.2f}"
                         if who == "fem_anim" else ""])
    return md_table(["scene", "tets", "frames", "run", "s/step", "Newton/step", "IPC share",
                     "retries (wall)", "crossed frames", "ratio to baseline",
                     "COM height diff, max (mm)",
                     f"within {1e3 * COM_TOLERANCE:g} mm until (s)",
                     "mean height diff at end (mm)"], rows)


def _kept_entries(path: Path, names: list[str], size: str) -> dict:
    """The entries of an earlier ``contact_set.json`` in ``path`` of the same size for the
    scenes not run now (each keeps its own command and machine line), by scene."""
    try:
        entries = json.loads(path.read_text())["scenes"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    return {e["scene"]: e for e in entries if isinstance(e, dict)
            and e.get("size") == size and e.get("scene") in SCENES and e["scene"] not in names}


def main(argv: list[str] | None = None) -> int:
    from fem_anim.bench.report import machine_text
    from fem_anim.console import OneLineParser, exit_status
    from fem_anim.petsc_options import init_petsc

    init_petsc([])
    p = OneLineParser(prog="fem-anim bench --contact", description=__doc__.split("\n")[0])
    p.add_argument("--size", choices=tuple(SIZES), default="full")
    p.add_argument("--only", default=",".join(SCENES))
    p.add_argument("--steps", type=int, default=None)
    p.add_argument("--out", default="demos/results/contact_set")
    p.add_argument("--no-pictures", action="store_true")
    args = None

    def run() -> int:
        nonlocal args
        args = p.parse_args(list(sys.argv[1:] if argv is None else argv))
        from mpi4py import MPI

        if MPI.COMM_WORLD.size > 1:  # both runs are serial by design (one process each)
            raise FemAnimError("fem-anim bench --contact runs serially: start it without "
                               "mpirun")
        names = [n.strip() for n in args.only.split(",") if n.strip()]
        for n in names:
            if n not in SCENES:
                raise FemAnimError(f"--only: unknown scene {n!r}; choose from "
                                   f"{', '.join(SCENES)}")
        if args.steps is not None and not 1 <= args.steps <= 100000:
            raise FemAnimError(f"--steps: must be between 1 and 100000, got {args.steps}")
        out = Path(args.out)
        products = ["contact_set.md", "contact_set.json"] + [
            f"{n}{s}" for n in names for s in (".toml", "_fem_anim.csv", "_baseline.csv",
                                                "_frames.npz", "_com_heights.csv",
                                                "_fem_anim.png", "_baseline.png")]
        check_may_write(out, products)
        command = ("fem-anim bench --contact " + " ".join(
            argv if argv is not None else sys.argv[1:])).strip()
        kept = _kept_entries(out / "contact_set.json", names, args.size)
        for n in names:
            entry = run_scene(n, args.size, out, args.steps, not args.no_pictures)
            load = f"{os.getloadavg()[0]:.1f}"
            kept[n] = {**entry, "command": command, "machine": machine_text(load)}
        for n, e in kept.items():  # older entries: the comparison again, from their frames
            if n not in names:
                data = np.load(out / f"{n}_frames.npz")
                com = [_com_heights(data["points"], data["cells"], data["body"], data[w])
                       for w in ("fem_anim", "baseline")]
                e.update(physics_check(*com))
        entries = [kept[n] for n in SCENES if n in kept]
        notes = "\n".join(f"* {e['scene']}: measured {e['machine']}; regenerate: "
                          f"`{e['command']}`." for e in entries)
        text = notes + "\n\n" + table(entries)
        write_product(out / "contact_set.json",
                      json.dumps({"scenes": entries}, indent=1).encode())
        write_product(out / "contact_set.md", (text + "\n").encode())
        print(text)
        return 0

    return exit_status(run, lambda: args.out)


if __name__ == "__main__":
    sys.exit(main())
