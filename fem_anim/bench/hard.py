"""The full default run on a ~60k-tetrahedron beam: plain Newton against fem_anim's menu.

    python -m fem_anim.bench.hard [SCENE] [--element-size H] [--preset P] [--out DIR]

Each configuration is a complete ``fem-anim run`` (60 steps of dt = 1/60 s, Newmark) in its
own process. "Plain" is what DOLFINx + SNES gives without fem_anim's safeguards: full Newton
steps (``-snes_linesearch_type basic``), no inversion filter, no adaptive dt; a variant keeps
the backtracking line search on the objective but not the filter. fem_anim's configuration
is its default (line search on g = +inf where det F <= 0, inversion filter, adaptive dt),
and the same with the shifted Hessian. Reported: whether the run finished, where and why it
stopped, Newton iterations, retries and wall time.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["CONFIGS", "hard_run", "run_case"]

HARD_ELEMENT_SIZE = 0.015  # 55k tetrahedra on the default beam
CONFIGS = (
    ("plain Newton (full steps, no filter, fixed dt)",
     ["solver.inversion_filter=false", "time.adaptive=false"],
     ["-snes_linesearch_type", "basic"]),
    ("Newton + backtracking on g, no filter, fixed dt",
     ["solver.inversion_filter=false", "time.adaptive=false"], []),
    ("fem_anim default (line search on g, J > 0 filter, adaptive dt)", [], []),
    ("fem_anim, shifted Hessian", ["solver.hessian=\"shift\""], []),
)


def run_case(scene_path, overrides, petsc, preset: str, timeout: float = 3600.0) -> dict:
    """One complete run in a subprocess; its outcome, stats and wall time."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "fem_anim", "run", *([scene_path] if scene_path else []),
               "-q", "-o", str(Path(tmp) / "run"), "--solver", preset,
               "--set", "output.render=false"]
        for o in overrides:
            cmd += ["--set", o]
        cmd += petsc
        env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
        start = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
        wall = time.perf_counter() - start
        stats = Path(tmp) / "run" / "stats.csv"
        if not stats.exists():
            stats = Path(tmp) / "run" / ".partial" / "stats.csv"
        rows = list(csv.DictReader(stats.open())) if stats.exists() else []
        error = [ln for ln in proc.stderr.splitlines() if ln.startswith("fem-anim: error:")]
        return {"finished": proc.returncode == 0, "wall": wall, "rows": rows,
                "error": error[-1][len("fem-anim: error: "):] if error else "",
                "steps": len(rows),
                "newton_its": sum(int(r["newton_its"]) for r in rows),
                "retries": sum(int(r["retries"]) for r in rows),
                "t_end": float(rows[-1]["time"]) if rows else 0.0}


def hard_run(scene_path, overrides, out: Path, log=print, h: float = HARD_ELEMENT_SIZE,
             preset: str = "cg-icc") -> str:
    """Run every configuration; the markdown section (also ``out/hard.md``)."""
    from .report import md_table

    body = []
    for label, sets, petsc in CONFIGS:
        r = run_case(scene_path, [*overrides, f"mesh.element_size={h}", *sets], petsc, preset)
        reason = r["error"].split("; the frames so far")[0]  # without the temporary path
        outcome = "finished" if r["finished"] else f"stopped: {reason}"
        log(f"  {label}: {outcome} ({r['steps']} steps to t = {r['t_end']:.3f} s, "
            f"{r['newton_its']} Newton its, {r['retries']} retries, {r['wall']:.0f} s)")
        body.append([label, "yes" if r["finished"] else "no", f"{r['t_end']:.3f}",
                     r["newton_its"], r["retries"], r["wall"], outcome.replace("|", "/")])
    text = ("## The 60k run\n\n"
            f"Default scene (neo-Hookean beam, Newmark, dt = 1/60 s, 60 steps), "
            f"mesh.element_size = {h} (55k tetrahedra at 0.015), preset {preset}, each a "
            "complete `fem-anim run`.\n\n"
            + md_table(["configuration", "finished", "t reached, s", "Newton its", "retries",
                        "wall s", "outcome"], body))
    (out / "hard.md").write_text(text + "\n", encoding="utf-8")
    return text


def main(argv: list[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="python -m fem_anim.bench.hard")
    p.add_argument("scene", nargs="?")
    p.add_argument("--element-size", type=float, default=HARD_ELEMENT_SIZE)
    p.add_argument("--preset", default="cg-icc")
    p.add_argument("--out", default="demos/results")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(hard_run(args.scene, [], out, h=args.element_size, preset=args.preset))
    return 0


if __name__ == "__main__":
    sys.exit(main())
