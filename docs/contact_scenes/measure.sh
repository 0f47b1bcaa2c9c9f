#!/bin/bash
# Runs the scenes of docs/contact.md's table ("Measured: energy and Newton iterations") and
# prints the table's numbers. Run from the repository root: bash docs/contact_scenes/measure.sh
set -e
out=${OUT:-/tmp/contact_measure}
run() { tag=$1; shift; .venv/bin/fem-anim run -q -o "$out/$tag" "$@"; }
run pile demos/pile.toml
run pile_norm demos/pile.toml --set 'solver.stopping="norm"'
run cubes docs/contact_scenes/stacked_cubes.toml
run cubes_norm docs/contact_scenes/stacked_cubes.toml --set 'solver.stopping="norm"'
run pile_decrement demos/pile.toml --set 'solver.stopping="decrement"' --set solver.decrement_tol=1e-10
run jelly demos/jelly_cube.toml
run ball_bdf2 docs/contact_scenes/ball_wall.toml --set 'time.integrator="bdf2"'
run ball_ie docs/contact_scenes/ball_wall.toml
run bar demos/twisted_bar.toml
.venv/bin/python - "$out" <<'PY'
import csv, json, pathlib, sys
for p in sorted(pathlib.Path(sys.argv[1]).iterdir()):
    rows = list(csv.DictReader(open(p / "stats.csv")))
    s = json.loads((p / "summary.json").read_text())
    e = s["energy"]
    its = [int(r["newton_its"]) for r in rows]
    rise = max(0.0, *(float(r["total_energy"]) - e["initial_energy"] for r in rows))
    print(f"{p.name}: {s['integrator']}, {len(rows)} steps, {sum(its) / len(its):.2f} "
          f"its/step (max {max(its)}; last 10 {sum(its[-10:]) / len(its[-10:]):.1f}), rise "
          f"{100 * rise / e['exchanged_energy']:.3g} %, round-off steps "
          f"{sum(r['snes_reason'] == '6' for r in rows)}")
PY
