"""The hanging beam side by side in fem_anim and its peers, at equal accuracy.

    python -m fem_anim.bench.peers [SCENE] [--sizes H,H] [--steps N] [--out DIR]

Same mesh (fem_anim's gmsh beam, its input arrays handed to every peer), same material
(stable neo-Hookean: the one model pbatoolkit and fem_anim share), same implicit Euler step
dt, same Newton tolerance (||grad g|| <= max(1e-12, 1e-8 ||grad g_0||)). Compared:

* fem_anim (DOLFINx + PETSc SNES): presets ``cholesky`` and ``cg-icc``, and ``cg-icc`` with
  ``solver.forcing = "adaptive"`` (Eisenstat-Walker Krylov tolerances; Newton still stops
  at the same residual test);
* the project's hand-assembled numpy/scipy Newton (:mod:`fem_anim.reference`, sparse LU);
* pbatoolkit (PyPI) in its own virtual environment (its numpy differs from the system's),
  run by :mod:`fem_anim.bench.pbat_worker`: Newton on its compiled stable neo-Hookean
  energy with Eigen's LDL^T, and its vertex block descent with 20 sweeps per step.

Accuracy: the tip (mean displacement of the vertices at x = max) over the steps, as the
largest deviation from fem_anim's exact-Newton trajectory relative to the largest tip
displacement. Time: mean wall seconds per step, and the ratio to fem_anim's.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fem_anim.errors import FemAnimError
from fem_anim.output.products import check_may_write, write_product

__all__ = ["main", "peer_table", "peer_python", "PEER_VENV"]

PEER_VENV = Path(os.environ.get("FEM_ANIM_PEER_VENV",
                                Path.home() / ".cache" / "fem_anim_peer" / "venv"))
PEER_SIZES = (0.025, 0.0145)  # 12.7k and 61.0k tetrahedra
VBD_SWEEPS = 20
REFERENCE_STEPS_LARGE = 3
SCENE_SETTINGS = ["material.model=\"stable_neohookean\"", "time.integrator=\"implicit_euler\"",
                  "output.render=false", "damping.beta=0"]  # the peers' beam is undamped


def peer_python(install: bool = True) -> Path | None:
    """The peer venv's python with pbatoolkit, made with pip on first use; None if it cannot.

    The reason is printed: the exact command and its last error line.
    """
    python = PEER_VENV / "bin" / "python"
    check = [str(python), "-c", "import pbatoolkit"]
    if python.exists() and subprocess.run(check, capture_output=True).returncode == 0:
        return python
    if not install:
        return None
    steps = [["/usr/bin/python3", "-m", "venv", str(PEER_VENV)],
             [str(python), "-m", "pip", "install", "-q", "pbatoolkit"], check]
    for cmd in steps:
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            tail = (proc.stderr.strip().splitlines() or ["?"])[-1]
            print(f"pbatoolkit unavailable: `{' '.join(cmd)}` failed: {tail}", file=sys.stderr)
            return None
    return python


#: fem_anim's configurations: (label, preset, scene overrides)
FEM_ANIM_CONFIGS = (("fem_anim cholesky", "cholesky", []),
                    ("fem_anim cg-icc", "cg-icc", []),
                    ("fem_anim cg-icc, forcing adaptive", "cg-icc",
                     ['solver.forcing="adaptive"']))


def _fem_anim(scene, preset: str, steps: int):
    from mpi4py import MPI

    from fem_anim.bench.worker import measure

    r = measure(scene, preset, steps, {}, MPI.COMM_SELF, tip=True)
    return np.array([s["wall"] for s in r["steps"]]), np.array(r["tip"]), r


def _reference(domain, scene, steps: int):
    from fem_anim import reference
    from fem_anim.reference.time_integrators import implicit_euler_step, initial_state

    mat = scene["material"]
    points, cells = domain.points, domain.cells
    pinned_vertices = points[:, 0] <= 1e-6
    pinned = np.repeat(pinned_vertices, 3)
    problem = reference.build_problem(points, cells, "stable_neohookean", mat["youngs_modulus"],
                                      mat["poisson_ratio"], mat["density"],
                                      scene["gravity"]["acceleration"], pinned)
    state = initial_state(problem, points.ravel())
    tip = points[:, 0] >= points[:, 0].max() - 1e-9
    times, path = [], []
    for _ in range(steps):
        start = time.perf_counter()
        state, _ = implicit_euler_step(problem, state, scene["time"]["dt"], rtol=1e-8,
                                       atol=1e-12)
        times.append(time.perf_counter() - start)
        path.append((state.x - points.ravel()).reshape(-1, 3)[tip].mean(axis=0))
    return np.array(times), np.array(path)


def _pbat(python: Path, domain, scene, steps: int, mode: str, sweeps: int = VBD_SWEEPS):
    mat = scene["material"]
    points, cells = domain.points, domain.cells
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(src, X=points, T=cells.astype(np.int64),
                 pinned=np.flatnonzero(points[:, 0] <= 1e-6),
                 tip=np.flatnonzero(points[:, 0] >= points[:, 0].max() - 1e-9),
                 rho=mat["density"], youngs=mat["youngs_modulus"], nu=mat["poisson_ratio"],
                 gravity=np.asarray(scene["gravity"]["acceleration"], float),
                 dt=scene["time"]["dt"], steps=steps, rtol=1e-8, atol=1e-12, mode=mode,
                 sweeps=sweeps)
        worker = Path(__file__).with_name("pbat_worker.py")
        proc = subprocess.run([str(python), str(worker), str(src), str(dst)],
                              capture_output=True, text=True, timeout=3600)
        if proc.returncode != 0:
            tail = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
            raise FemAnimError(f"pbatoolkit worker ({mode}) failed: {tail}")
        out = np.load(dst)
        return out["times"], out["tip"]


def compare(scene_path, overrides, h: float, steps: int, python: Path | None, log=print):
    """Rows [solver, tets, s/step, ratio to fem_anim cholesky, tip error] for one mesh."""
    from mpi4py import MPI

    from fem_anim.mesh.build import build_mesh
    from fem_anim.scene.loading import load_scene

    settings = [*overrides, *SCENE_SETTINGS, f"mesh.element_size={h}", f"time.steps={steps}"]
    scene = load_scene(scene_path, settings)
    domain = build_mesh(MPI.COMM_SELF, scene)
    runs = {}
    for label, preset, extra in FEM_ANIM_CONFIGS:
        times, tip, r = _fem_anim(load_scene(scene_path, [*settings, *extra]), preset, steps)
        runs[label] = (times, tip)
    tets = r["tets"]
    # the numpy reference costs ~25x fem_anim's step: on large meshes it runs the first
    # REFERENCE_STEPS_LARGE steps only (its tip is compared over those)
    ref_steps = steps if tets <= 20000 else min(steps, REFERENCE_STEPS_LARGE)
    runs["numpy/scipy reference Newton"] = _reference(domain, scene, ref_steps)
    if python is not None:
        runs["pbatoolkit Newton (Eigen LDLT)"] = _pbat(python, domain, scene, steps, "newton")
        runs[f"pbatoolkit VBD, {VBD_SWEEPS} sweeps"] = _pbat(python, domain, scene, steps,
                                                             "vbd")
    exact = runs["fem_anim cholesky"][1]
    scale = np.abs(exact).max()
    base = float(np.mean(runs["fem_anim cholesky"][0][1:]))
    rows = []
    for name, (times, tip) in runs.items():
        per_step = float(np.mean(times[1:])) if len(times) > 1 else float(times[0])
        error = float(np.abs(np.asarray(tip) - exact[:len(tip)]).max() / scale)
        rows.append([name, tets, per_step, per_step / base, error])
        log(f"  {tets} tets {name}: {per_step:.3f} s/step ({per_step / base:.2f}x), "
            f"tip deviation {error:.2e}")
    return rows


def peer_table(scene_path, overrides, out: Path, log=print, sizes=PEER_SIZES,
               steps: int = 10) -> str:
    """The side-by-side table (also written to ``out/peers.md``)."""
    from fem_anim.bench.report import machine_text, md_table

    python = peer_python()
    rows = []
    for h in sizes:
        rows += compare(scene_path, overrides, h, steps, python, log)
    note = "" if python is not None else (
        "\n\npbatoolkit could not be installed or imported here (see the message above); "
        "only the numpy reference is compared.")
    text = ("## Peers\n\n"
            f"Measured {machine_text(_load())}. Regenerate: `python -m fem_anim.bench.peers`."
            f"\nHanging beam, stable neo-Hookean, implicit Euler, dt = 1/60 s, {steps} steps "
            "from rest, same gmsh mesh; Newton to ||grad g|| <= max(1e-12, 1e-8 "
            "||grad g_0||) for every Newton solver. 'ratio' is the time per step (steps 2.."
            f"{steps}) over fem_anim's cholesky preset; 'tip dev.' the largest deviation of "
            "the tip's mean displacement from fem_anim cholesky's, relative to the largest "
            "tip displacement (on meshes over 20k tetrahedra the numpy reference runs "
            f"{REFERENCE_STEPS_LARGE} steps only). pbatoolkit's stable neo-Hookean omits the "
            "log term of fem_anim's (Smith et al. 2018 simplified) and is given lambda + mu "
            "so the rest response is the same: its Newton run differs from fem_anim's by this "
            "model "
            "difference, its VBD run by that plus VBD's truncation at a fixed sweep count.\n\n"
            + md_table(["solver", "tets", "s/step", "ratio", "tip dev."], rows) + note)
    write_product(out / "peers.md", (text + "\n").encode())
    return text


def _load() -> str:
    try:
        return open("/proc/loadavg", encoding="ascii").read().split()[0]
    except OSError:
        return "?"


def main(argv: list[str] | None = None) -> int:
    from fem_anim.console import OneLineParser, exit_status
    from fem_anim.petsc_options import init_petsc

    init_petsc([])

    p = OneLineParser(prog="python -m fem_anim.bench.peers", description=__doc__.split("\n")[0])
    p.add_argument("scene", nargs="?")
    p.add_argument("--sizes", default=",".join(map(str, PEER_SIZES)))
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--set", dest="overrides", action="append", default=[])
    p.add_argument("--out", default="demos/results/peers")
    args = None

    def run() -> int:
        nonlocal args
        args = p.parse_args(list(sys.argv[1:] if argv is None else argv))
        try:
            sizes = [float(v) for v in args.sizes.split(",")]
        except ValueError:
            raise FemAnimError(f"--sizes: not a list of numbers: {args.sizes}") from None
        if not 2 <= args.steps <= 1000:
            raise FemAnimError(f"--steps: must be between 2 and 1000, got {args.steps}")
        out = Path(args.out)
        check_may_write(out, ["peers.md"])  # before the runs, not after
        print(peer_table(args.scene, args.overrides, out, sizes=sizes, steps=args.steps))
        return 0

    return exit_status(run, lambda: args.out)


if __name__ == "__main__":
    sys.exit(main())
