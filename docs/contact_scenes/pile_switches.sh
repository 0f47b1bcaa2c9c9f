#!/bin/bash
# The 4-box pile (python -m fem_anim.bench.contact_cost's scene) stepped by "today"
# (commit 7a2556b), by this tree with the three changes of docs/contact.md's "The 4-box
# pile: the cost of an iteration and the landing" switched off ("base": BLOCKED_ASSEMBLY,
# GROW_AT_ONCE and HALVE_CLIPPED set to False before fem_anim.cli.main, which reproduces
# the tree before them bit for bit) and by this tree as it is ("new"), interleaved
# old, base, new, REPS times. Run from the repository root:
#   bash docs/contact_scenes/pile_switches.sh H STEPS REPS OUT
# e.g. bash docs/contact_scenes/pile_switches.sh 0.01 10 2 /tmp/pile_switches
# Like pile_today.sh it makes a detached worktree of 7a2556b in OUT/old (its own .venv)
# unless one is there, writes OUT/pile.toml, runs each side as `fem-anim run OUT/pile.toml
# --set time.steps=STEPS --set output.render=false` under /usr/bin/time -v with one
# OpenBLAS/OpenMP thread, and prints per run: Newton iterations per step (and each step's),
# the steps not meeting the stopping test (SNES reason <= 0, 6 or 7), factorisations,
# s/step (summary.json's stepping + output wall time over STEPS), the process's CPU time
# and the load average when the run started. Remove the old worktree afterwards with:
# git worktree remove --force OUT/old
set -e
H=$1; STEPS=$2; REPS=$3; OUT=$4
if [ -z "$OUT" ]; then echo "usage: $0 H STEPS REPS OUT" >&2; exit 2; fi
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
NEW=$(pwd)
if [ ! -x "$OUT/old/.venv/bin/fem-anim" ]; then
  git worktree add --detach "$OUT/old" 7a2556b
  (cd "$OUT/old" && bash .ci/setup)
fi
.venv/bin/python -c "from fem_anim.bench.contact_cost import pile_scene; import sys; \
open(sys.argv[1], 'w').write(pile_scene(float(sys.argv[2])))" "$OUT/pile.toml" "$H"
cat > "$OUT/base.py" <<'PY'
import sys
import fem_anim.problem.matrices as matrices
import fem_anim.solver.minimiser as minimiser
matrices.BLOCKED_ASSEMBLY = matrices.GROW_AT_ONCE = minimiser.HALVE_CLIPPED = False
from fem_anim.cli import main
sys.exit(main(sys.argv[1:]))
PY
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
ARGS=(run "$OUT/pile.toml" --set time.steps="$STEPS" --set output.render=false)
for r in $(seq 1 "$REPS"); do
  for side in old base new; do
    run=$OUT/${side}_r$r
    rm -rf "$run"
    echo "$side r$r load $(cut -d' ' -f1 /proc/loadavg)" >> "$OUT/log"
    case $side in
      old) (cd "$OUT/old" && /usr/bin/time -v -o "$run.time" .venv/bin/fem-anim "${ARGS[@]}" \
              -o "$run" > "$run.log" 2>&1) ;;
      base) /usr/bin/time -v -o "$run.time" .venv/bin/python "$OUT/base.py" "${ARGS[@]}" \
              -o "$run" > "$run.log" 2>&1 ;;
      new) /usr/bin/time -v -o "$run.time" .venv/bin/fem-anim "${ARGS[@]}" \
              -o "$run" > "$run.log" 2>&1 ;;
    esac
  done
done
exec .venv/bin/python - "$OUT" <<'PY'
import csv, json, re, sys
from pathlib import Path

out = Path(sys.argv[1])
order = {"old": 0, "base": 1, "new": 2}
loads = dict(re.findall(r"^(\w+ r\d+) load ([\d.]+)$", (out / "log").read_text(), re.M))
print("| run | Newton its/step | its per step | steps not meeting the test | factorisations "
      "| s/step (wall) | process CPU (s) | load at start |")
print("|---|---|---|---|---|---|---|---|")
runs = [p for p in out.glob("*_r[0-9]*") if (p / "summary.json").is_file()]
for run in sorted(runs, key=lambda p: (int(p.name.split("_r")[1]), order[p.name.split("_r")[0]])):
    summary = json.loads((run / "summary.json").read_text())
    rows = list(csv.DictReader(open(run / "stats.csv", newline="")))
    timing = (run.parent / (run.name + ".time")).read_text()
    cpu = sum(float(re.search(rf"{k} time \(seconds\): ([\d.]+)", timing).group(1))
              for k in ("User", "System"))
    n = summary["steps"]
    loop = summary["wall"]["stepping_s"] + summary["wall"].get("output_s", 0.0)
    its = [int(r["newton_its"]) for r in rows]
    unmet = sum(int(r["snes_reason"]) <= 0 or int(r["snes_reason"]) in (6, 7) for r in rows)
    factor = sum(int(r["factorisations"]) for r in rows) if "factorisations" in rows[0] else "-"
    side, rep = run.name.split("_r")
    print(f"| {run.name} | {sum(its) / n:.1f} | {' '.join(map(str, its))} | {unmet} | "
          f"{factor} | {loop / n:.3f} | {cpu:.1f} | {loads.get(f'{side} r{rep}', '?')} |")
PY
