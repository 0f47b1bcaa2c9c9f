#!/bin/bash
# The 4-box pile (python -m fem_anim.bench.contact_cost's scene) stepped by "today"
# (commit 7a2556b, the last before issues 28-33) and by this tree, interleaved A/B/A/B
# (docs/contact.md, "The 4-box pile against today and against the baseline").
# Run from the repository root:
#   bash docs/contact_scenes/pile_today.sh H STEPS REPS OUT
# e.g. bash docs/contact_scenes/pile_today.sh 0.01 10 2 /tmp/pile_today
# It makes a detached worktree of 7a2556b in OUT/old (with its own .venv from .ci/setup)
# unless one is there, writes OUT/pile.toml (contact_cost.pile_scene(H); both trees accept
# it unchanged), runs `fem-anim run OUT/pile.toml --set time.steps=STEPS --set
# output.render=false` in the old tree and in this one, one after the other, REPS times,
# under /usr/bin/time -v with one OpenBLAS/OpenMP thread each, and prints per run: Newton
# iterations per step, s/step (the stepping loop's wall time, discarded tries and the
# per-step output included: summary.json's wall.stepping_s + wall.output_s over STEPS;
# 7a2556b's stepping_s alone leaves out discarded tries), retries, the largest number of
# active pairs, and the process's wall and CPU time (mesh and set-up included). Remove the
# old worktree afterwards with: git worktree remove --force OUT/old
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
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
for r in $(seq 1 "$REPS"); do
  for side in old new; do
    if [ $side = old ]; then tree=$OUT/old; else tree=$NEW; fi
    run=$OUT/${side}_r$r
    rm -rf "$run"
    echo "$(date -u +%T) $side r$r: load $(cut -d' ' -f1 /proc/loadavg)" >&2
    (cd "$tree" && /usr/bin/time -v -o "$run.time" .venv/bin/fem-anim run "$OUT/pile.toml" \
        --set time.steps="$STEPS" --set output.render=false -o "$run" > "$run.log" 2>&1)
  done
done
echo "$(date -u +%T) done: load $(cut -d' ' -f1 /proc/loadavg)" >&2
exec .venv/bin/python - "$OUT" <<'PY'
import csv, json, re, sys
from pathlib import Path

out = Path(sys.argv[1])
print("| run | tets | steps | Newton its/step | s/step (wall) | retries | max pairs "
      "| process wall (s) | process CPU (s) |")
print("|---|---|---|---|---|---|---|---|---|")
for run in sorted(out.glob("*_r[0-9]*"), key=lambda p: (p.name.split("_r")[1], p.name)):
    if not (run / "summary.json").is_file():  # not a finished run
        continue
    summary = json.loads((run / "summary.json").read_text())
    rows = list(csv.DictReader(open(run / "stats.csv", newline="")))
    timing = (run.parent / (run.name + ".time")).read_text()
    cpu = sum(float(re.search(rf"{k} time \(seconds\): ([\d.]+)", timing).group(1))
              for k in ("User", "System"))
    clock = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)",
                      timing).group(1).split(":")
    wall = sum(float(x) * 60 ** i for i, x in enumerate(reversed(clock)))
    n = summary["steps"]
    loop = summary["wall"]["stepping_s"] + summary["wall"]["output_s"]
    cells = run / "final.vtu"
    tets = re.search(rb'NumberOfCells="(\d+)"', cells.read_bytes()[:4000])
    print(f"| {run.name} | {tets.group(1).decode() if tets else '?'} | {n} | "
          f"{sum(int(r['newton_its']) for r in rows) / n:.1f} | {loop / n:.3f} | "
          f"{summary['retries']} | {max(int(r['contact_pairs']) for r in rows)} | "
          f"{wall:.1f} | {cpu:.1f} |")
PY
