#!/bin/bash
# The preview on a contact scene (docs/contact.md, "The preview on contact scenes"): runs
# demos/pile.toml with --preview (steps solved to the stopping test), with the one-step
# preview's keys named by hand (cg-icc, and MUMPS Cholesky), and exact; prints the table's
# numbers. From the repository root: bash docs/contact_scenes/measure_preview.sh
set -e
out=${OUT:-/tmp/preview_measure}
one="--set solver.max_iterations=1 --set solver.on_budget=\"accept\""
run() { tag=$1; shift; .venv/bin/fem-anim run -q -o "$out/$tag" --set output.render=false "$@"; }
run 1_preview demos/pile.toml --preview
run 2_one_step_cg_icc demos/pile.toml $one --solver cg-icc --set solver.petsc.ksp_rtol=1e-4
run 3_one_step_cholesky demos/pile.toml $one --solver cholesky
run 4_exact demos/pile.toml
.venv/bin/python - "$out" <<'PY'
import csv, json, pathlib, sys
for p in sorted(pathlib.Path(sys.argv[1]).iterdir()):
    rows = list(csv.DictReader(open(p / "stats.csv")))
    s = json.loads((p / "summary.json").read_text())
    e0, ex = s["energy"]["initial_energy"], s["energy"]["exchanged_energy"]
    E = [float(r["total_energy"]) for r in rows]
    its = [int(r["newton_its"]) for r in rows]
    wall = sum(float(r["step_wall_s"]) for r in rows)
    print(f"{p.name}: {len(rows)} steps to t = {float(rows[-1]['time']):.2f} s, retries "
          f"{sum(int(r['retries']) for r in rows)}, {sum(its) / len(its):.2f} its/step, "
          f"{wall / len(rows):.3f} s/step, rise {100 * max(0.0, max(E) - e0) / ex:.3g} % of "
          f"the exchanged {ex:.4g} J, final {E[-1]:.4g} J")
PY
