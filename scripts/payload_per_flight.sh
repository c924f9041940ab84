#!/usr/bin/env bash
# Fly the payload cases of docs/gap.md ("A payload on a cable") with python -m quadsim.fly and
# judge them per flight against 5 generated nominal flights: bash scripts/payload_per_flight.sh OUT
set -euo pipefail
out=${1:?usage: payload_per_flight.sh OUT}
mkdir -p "$out"
noise="--sensor-noise position=5e-4,velocity=0.01,attitude=2e-3,gyro=0.02,accel=0.1,rotor=10"
fly() { python -m quadsim.fly --model crazyflie21 --duration 5 $noise "$@" > /dev/null; }
i=0
for path_speed in figure8:1.0 figure8:1.5 steps:1.0 lissajous:1.0 steps:1.0; do
  fly --path "${path_speed%%:*}" --speed "${path_speed##*:}" --seed $i -o "$out/ref$i.csv.gz"
  i=$((i + 1))
done
fly --path steps --speed 1.0 --seed 40 --effect cable_payload:mass=0.0074,length=0.5 \
    -o "$out/cable_steps.csv.gz"
fly --path figure8 --speed 1.5 --seed 42 --effect cable_payload:mass=0.0074,length=0.5 \
    -o "$out/cable_figure8.csv.gz"
fly --path figure8 --speed 1.0 --seed 41 --effect mass_offset:mass=0.0037 -o "$out/mass.csv.gz"
python -m quadsim.gap --model crazyflie21 --per-flight "$out"/cable_steps.csv.gz \
    "$out"/cable_figure8.csv.gz "$out"/mass.csv.gz --reference "$out"/ref*.csv.gz \
    --workers 1 --json "$out/per_flight.json" --report "$out/per_flight.html"
