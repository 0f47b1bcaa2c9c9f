#!/usr/bin/env bash
# The solver's budget (solver.mode = "preview") as one more axis of the trade study
# (fem_anim.bench.trade), one command:
#   bash demos/trade_study_solver.sh     -> demos/results/trade_study/solver_budget/trade_study.{csv,png,md}
# 0.6 s of the hanging beam (P1, element size 0.1 m) from solver.mode = "preview" (cg-icc, CG to
# 1e-4, hessian auto, budget accepted): time step x Newton iterations per step (1, 2, 4, or
# 50 = to the residual test) x how often the Hessian is rebuilt; each against the same fine
# reference as demos/trade_study.sh (solved exactly).
set -euo pipefail
cd "$(dirname "$0")/.."
exec .venv/bin/fem-anim bench demos/hanging_beam.toml --set time.steps=36 \
  --set mesh.element_size=0.1 --set 'solver.mode="preview"' --set 'solver.preset="cg-icc"' \
  --sweep time.dt=0.06666666666666667,0.03333333333333333,0.016666666666666666 \
  --sweep solver.max_iterations=1,2,4,50 \
  --sweep solver.hessian_update=every_iteration,every_step \
  --reference mesh.element_size=0.07 --reference time.dt=0.008333333333333333 \
  --reference 'solver.mode="exact"' --reference 'solver.preset="cholesky"' \
  --repeats 3 -o demos/results/trade_study/solver_budget "$@"
