#!/bin/bash
# Runs docs/contact_scenes/incompressible_drop.toml as mixed nu = 0.5 (the scene; and with
# backtracking instead of its default secant line search), P2
# displacement nu = 0.45 and P1 displacement nu = 0.45, and prints the numbers of
# docs/contact.md's table ("P2 and mixed bodies in contact"). From the repository root:
#     bash docs/contact_scenes/measure_p2_mixed.sh
set -e
out=${OUT:-/tmp/p2_mixed_measure}
scene=docs/contact_scenes/incompressible_drop.toml
mkdir -p "$out"
# the displacement variants: nu = 0.45 in both bodies (--set does not reach into [[body]])
sed 's/poisson_ratio = 0.5,/poisson_ratio = 0.45,/; s/formulation = "mixed"/formulation = "displacement"/' \
    $scene > "$out/drop_displacement.toml"
run() { tag=$1; shift; .venv/bin/fem-anim run -q -o "$out/$tag" --set output.render=false "$@"; }
run mixed_p2 $scene
run mixed_p2_bt $scene --set 'solver.petsc.snes_linesearch_type="bt"'
run displacement_p2 "$out/drop_displacement.toml"
run displacement_p1 "$out/drop_displacement.toml" --set element.degree=1
.venv/bin/python - "$out" <<'PY'
import csv, json, pathlib, sys
for p in sorted(q for q in pathlib.Path(sys.argv[1]).iterdir() if q.is_dir()):
    rows = list(csv.DictReader(open(p / "stats.csv")))
    s = json.loads((p / "summary.json").read_text())
    e = s["energy"]
    its = [int(r["newton_its"]) for r in rows]
    rise = max(0.0, *(float(r["total_energy"]) - e["initial_energy"] for r in rows))
    wall = sum(float(r["step_wall_s"]) for r in rows)
    print(f"{p.name}: {len(rows)} steps, {wall / len(rows):.3f} s/step, "
          f"{sum(its) / len(its):.2f} its/step (max {max(its)}), retries "
          f"{sum(int(r['retries']) for r in rows)}, max pairs "
          f"{max(int(r['contact_pairs']) for r in rows)}, smallest distance "
          f"{min(float(r['min_distance']) for r in rows):.3g} m, energy rise "
          f"{100 * rise / e['exchanged_energy']:.3g} % of the exchanged "
          f"{e['exchanged_energy']:.4g} J, final total {float(rows[-1]['total_energy']):.4g} J")
PY
