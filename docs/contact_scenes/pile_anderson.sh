#!/bin/bash
# The Anderson-mixing experiment of docs/contact.md ("Accelerating the projected Newton
# iteration: Anderson mixing, not kept"). The mixing is not in the package: it is the patch
# docs/contact_scenes/anderson_precheck.patch (fem_anim/solver/minimiser.py, switched by
# ANDERSON_MEMORY, 0 = off, and ANDERSON_RESIDUAL, ANDERSON_RATE, ANDERSON_CAP,
# ANDERSON_PAIR_RESET), applied to a detached worktree of c8c9e54 in OUT/tree and imported
# from there (PYTHONPATH) by this tree's .venv. Run from the repository root:
#   bash docs/contact_scenes/pile_anderson.sh OUT [VARIANT ...]
# VARIANT is NAME:M:RESIDUAL:RATE:CAP:PAIR_RESET (default: the table's rows); each runs on
# the pile at H = 0.02 and 0.01 (python -m fem_anim.bench.contact_cost's scene, 10 steps),
# demos/pile.toml (30 steps) and the default scene (60 steps), one after the other, one
# OpenBLAS/OpenMP thread, under /usr/bin/time -v, and prints per run the Newton iterations
# a step, the process CPU time and the load average when it started. Every pile run is then
# re-checked with python -m fem_anim.bench.step_residuals (largest ||r|| over the largest
# force term). SCENES="p02 demo" (say) runs only those scenes, PILE_STEPS and DEMO_STEPS
# change the 10 and 30 steps. Remove the worktree
# afterwards with: git worktree remove --force OUT/tree
set -e
OUT=$1; shift || true
if [ -z "$OUT" ]; then echo "usage: $0 OUT [NAME:M:RESIDUAL:RATE:CAP:PAIR_RESET ...]" >&2; exit 2; fi
VARIANTS=("$@")
if [ ${#VARIANTS[@]} -eq 0 ]; then
  VARIANTS=(off:0:1:0.5:10:1 Y3:3:0:0.5:10:1 Y3u:3:0:0:1e30:1 R1:1:1:0.5:10:1 R3:3:1:0.5:10:1
            R5:5:1:0.5:10:1 R3u:3:1:0:1e30:1)
fi
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
TOP=$(pwd)
if [ ! -d "$OUT/tree" ]; then
  git worktree add --detach "$OUT/tree" c8c9e54
  git -C "$OUT/tree" apply "$TOP/docs/contact_scenes/anderson_precheck.patch"
fi
.venv/bin/python -c "from fem_anim.bench.contact_cost import pile_scene; import sys; \
open(sys.argv[1] + '/pile02.toml', 'w').write(pile_scene(0.02)); \
open(sys.argv[1] + '/pile01.toml', 'w').write(pile_scene(0.01))" "$OUT"
cat > "$OUT/drv.py" <<'PY'
import os, sys
import fem_anim.solver.minimiser as minimiser
m, res, rate, cap, pairs = os.environ["VARIANT"].split(":")[1:]
minimiser.ANDERSON_MEMORY, minimiser.ANDERSON_RESIDUAL = int(m), res == "1"
minimiser.ANDERSON_RATE, minimiser.ANDERSON_CAP = float(rate), float(cap)
minimiser.ANDERSON_PAIR_RESET = pairs == "1"
from fem_anim.cli import main
sys.exit(main(sys.argv[1:]))
PY
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 PYTHONPATH="$OUT/tree"
for S in ${SCENES:-p02 p01 demo default}; do
  case $S in
    p02) A=(run "$OUT/pile02.toml" --set time.steps="${PILE_STEPS:-10}") ;;
    p01) A=(run "$OUT/pile01.toml" --set time.steps="${PILE_STEPS:-10}") ;;
    demo) A=(run demos/pile.toml --set time.steps="${DEMO_STEPS:-30}") ;;
    default) A=(run --set time.steps=60) ;;
  esac
  for V in "${VARIANTS[@]}"; do
    run=$OUT/${V%%:*}_$S
    rm -rf "$run"
    echo "$(basename "$run") load $(cut -d' ' -f1 /proc/loadavg)" >> "$OUT/log"
    VARIANT=$V /usr/bin/time -v -o "$run.time" .venv/bin/python "$OUT/drv.py" "${A[@]}" \
      --set output.render=false -o "$run" > "$run.log" 2>&1
    case $S in
      p02) .venv/bin/python -m fem_anim.bench.step_residuals "$OUT/pile02.toml" "$run" \
             > "$run.residuals.md" ;;
      p01) .venv/bin/python -m fem_anim.bench.step_residuals "$OUT/pile01.toml" "$run" \
             > "$run.residuals.md" ;;
    esac
  done
done
exec .venv/bin/python - "$OUT" <<'PY'
import csv, re, sys
from pathlib import Path

out = Path(sys.argv[1])
load = dict(line.split(" load ") for line in (out / "log").read_text().splitlines())
print("| run | Newton its/step | max | process CPU (s) | load | largest ||r|| / force |")
print("|---|---|---|---|---|---|")
for stats in sorted(out.glob("*_*/stats.csv")):
    run = stats.parent
    its = [int(r["newton_its"]) for r in csv.DictReader(open(stats))]
    t = Path(str(run) + ".time").read_text()
    cpu = sum(float(re.search(k + r" time \(seconds\): ([\d.]+)", t).group(1))
              for k in ("User", "System"))
    res = Path(str(run) + ".residuals.md")
    worst = res.read_text().split("largest: ")[-1].strip() if res.exists() else "-"
    print(f"| {run.name} | {sum(its) / len(its):.2f} | {max(its)} | {cpu:.1f} | "
          f"{load.get(run.name, '-').strip()} | {worst} |")
PY
