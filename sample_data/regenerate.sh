#!/usr/bin/env bash
# Regenerates the synthetic sample data with the built tbsp (deterministic).
set -euo pipefail
cd "$(dirname "$0")"
TBSP=${TBSP:-../build/plugins/tbsp}
"$TBSP" generate bumpy-bar --out bumpy_bar.off --rings 60 --segments 24
"$TBSP" synth-scan --mesh bumpy_bar.off --out-cloud bar_scan.ply --out-markers bar_markers.json \
  --points 12000 --bend 80 --twist 45 --scale 1.5 --noise 0.002 --outliers 0.05 --hole 0.25 --markers 16 --seed 7
