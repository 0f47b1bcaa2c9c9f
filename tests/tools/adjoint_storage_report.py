"""The numbers of docs/gradients.md's memory section: where the forward states are kept
(memory, disk, revolve with a few checkpoint counts), what it costs in memory and time.

Each configuration runs in a process of its own (so its peak resident memory is its own):
the default scene (``fem_anim/default_scene.toml``, Newmark, 1662 dofs) for STEPS steps,
J the centre of mass and one vertex at the final time, parameters E, nu, rho; one
evaluation (forward run, then backward sweep, recomputation included). Printed per
configuration, as one JSON line: the forward and backward wall times, the forward steps
the sweep recomputed and the schedule's prediction, the most states the tape held and
their bytes, this rank's state files' bytes (disk), the resident memory after building
the model and at the end (``ru_maxrss``), J and the gradient (equal across
configurations: the largest relative difference to memory's is printed at the end).

Usage::

    .venv/bin/python tests/tools/adjoint_storage_report.py [STEPS] [CONFIG ...]
    .venv/bin/python tests/tools/adjoint_storage_report.py --side-by-side STEPS [CONFIG ...]

CONFIG is ``memory``, ``disk`` or ``revolve:C``; default STEPS = 1000 and
``memory disk revolve:100 revolve:30 revolve:10``. ``--side-by-side`` runs the
configurations' evaluations interleaved in one process and one model, two rounds, for
time ratios under the same load (memory is not separated there).
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np

CONFIGS = ["memory", "disk", "revolve:100", "revolve:30", "revolve:10"]


def resident_mib() -> float:
    """This process's resident memory now (MiB, /proc/self/status VmRSS)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def measure(steps: int, config: str) -> dict:
    """One configuration, in this process."""
    from fem_anim.adjoint import AdjointModel, CentreOfMassTarget, PointTarget
    from fem_anim.adjoint.schedule import BinomialSchedule
    from fem_anim.scene.loading import load_scene

    storage, _, count = config.partition(":")
    checkpoints = int(count) if count else None
    scene = load_scene(None, [f"time.steps={steps}"])
    model = AdjointModel(scene, ["material.youngs_modulus", "material.poisson_ratio",
                                 "material.density"], storage=storage, checkpoints=checkpoints)
    t = steps * scene["time"]["dt"]
    objective = CentreOfMassTarget([[0.5, 0.0, -0.05]], [t]) + \
        PointTarget([1.0, 0.1, 0.1], [[1.0, 0.1, 0.0]], [t])
    built = resident_mib()
    J, grad = model.evaluate(model.parameters.values(), objective)
    tape = model.tape
    predicted = BinomialSchedule(steps, checkpoints).recomputations() \
        if storage == "revolve" else 0
    out = {"config": config, "steps": steps, "dofs": int(model.problem.u.x.array.size),
           "forward_s": model.timing["forward"], "backward_s": model.timing["backward"],
           "recomputed": tape.recomputed, "predicted": predicted,
           "mismatches": tape.replay_mismatches, "peak_stored": tape.peak_stored,
           "peak_state_mib": tape.peak_nbytes / 2**20, "disk_mib": tape.disk_bytes / 2**20,
           "rss_built_mib": built,
           "maxrss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
           "J": J, "grad": [float(g) for g in grad]}
    tape.close()
    return out


def side_by_side(steps: int, configs: list[str], rounds: int) -> None:
    """The configurations' evaluations interleaved in one process and one model (the
    machine's load then falls on all of them alike): forward and backward times per round."""
    from fem_anim.adjoint import AdjointModel, CentreOfMassTarget, PointTarget
    from fem_anim.scene.loading import load_scene

    scene = load_scene(None, [f"time.steps={steps}"])
    model = AdjointModel(scene, ["material.youngs_modulus", "material.poisson_ratio",
                                 "material.density"])
    t = steps * scene["time"]["dt"]
    objective = CentreOfMassTarget([[0.5, 0.0, -0.05]], [t]) + \
        PointTarget([1.0, 0.1, 0.1], [[1.0, 0.1, 0.0]], [t])
    for r in range(rounds):
        for config in configs:
            storage, _, count = config.partition(":")
            model.storage, model.checkpoints = storage, int(count) if count else None
            J, grad = model.evaluate(model.parameters.values(), objective)
            print(json.dumps({"round": r, "config": config, "steps": steps,
                              "forward_s": model.timing["forward"],
                              "backward_s": model.timing["backward"],
                              "recomputed": model.tape.recomputed, "J": J,
                              "grad": [float(g) for g in grad]}), flush=True)
            model.tape.close()


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--side-by-side":
        side_by_side(int(sys.argv[2]), sys.argv[3:] or CONFIGS, 2)
        return
    if len(sys.argv) > 1 and sys.argv[1] == "--one":
        print("RESULT " + json.dumps(measure(int(sys.argv[2]), sys.argv[3])), flush=True)
        return
    steps = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    configs = sys.argv[2:] or CONFIGS
    rows = []
    for config in configs:
        done = subprocess.run([sys.executable, __file__, "--one", str(steps), config],
                              capture_output=True, text=True)
        line = [x for x in done.stdout.splitlines() if x.startswith("RESULT ")]
        if done.returncode != 0 or not line:
            print(f"{config}: failed ({done.returncode}): {done.stderr.strip()[-400:]}")
            continue
        rows.append(json.loads(line[0][7:]))
        print(json.dumps(rows[-1]), flush=True)
    base = next((r for r in rows if r["config"] == "memory"), None)
    print("| storage | forward (s) | backward (s) | backward / forward | recomputed steps "
          "(predicted) | states held (MiB) | files (MiB) | peak RSS (MiB) | max rel. "
          "gradient difference to memory |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        diff = float(np.max(np.abs(np.subtract(r["grad"], base["grad"])) /
                            np.abs(base["grad"]))) if base else float("nan")
        print(f"| {r['config']} | {r['forward_s']:.1f} | {r['backward_s']:.1f} | "
              f"{r['backward_s'] / r['forward_s']:.2f} | {r['recomputed']} "
              f"({r['predicted']}) | {r['peak_stored']} ({r['peak_state_mib']:.1f}) | "
              f"{r['disk_mib']:.1f} | {r['maxrss_mib']:.0f} | {diff:.1e} |")


if __name__ == "__main__":
    main()
