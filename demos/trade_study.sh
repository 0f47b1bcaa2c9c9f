#!/usr/bin/env bash
# The speed-accuracy trade study of the default scene (fem_anim.bench.trade), one command:
#   bash demos/trade_study.sh            -> demos/results/trade_study/trade_study.{csv,png,md}
# 0.6 s of the hanging beam; time step x element degree x element size x integrator x mass.
set -euo pipefail
cd "$(dirname "$0")/.."
exec .venv/bin/fem-anim bench demos/hanging_beam.toml --set time.steps=36 \
  --sweep time.dt=0.06666666666666667,0.03333333333333333,0.016666666666666666 \
  --sweep element.degree=1,2 --sweep mesh.element_size=0.14,0.1 \
  --sweep time.integrator=newmark,implicit_euler --sweep material.mass=consistent,lumped \
  --reference mesh.element_size=0.07 --reference time.dt=0.008333333333333333 \
  --repeats 3 -o demos/results/trade_study "$@"
