#!/usr/bin/env bash
# Responsiveness of tbsp-studio while the TetDeformer iterates (issue: the VTK app). Runs the
# scripted drag of the ui test (bumpy bar, ~5.9k tets, 300 iterations) RUNS times under Xvfb and
# prints one row per run: event-loop latency of a 10 ms UI timer (median / p95 / max), view
# updates and their time. Goal: max <= 33 ms (one 30 Hz frame). Usage: bench/bench_studio.sh [RUNS]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
runs=${1:-5}
studio=$root/build/vtk_ui/tbsp-studio
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cat > "$work/script.json" <<JSON
{"actions": [
  {"edit": {"mesh": "$root/sample_data/bumpy_bar.off", "tets": 5000}},
  {"select": {"rect": [0, 0, 140, 600]}}, {"add_handle": "selection"},
  {"select": {"rect": [660, 0, 800, 600]}}, {"add_handle": "selection"},
  {"iterate": 5}, {"reset_measurements": 0},
  {"drag": {"handle": 1, "translate": [-0.2, 0.35, 0], "rotate": {"axis": [0, 0, 1], "degrees": 80, "center": [0.95, 0, 0]}}},
  {"iterate": 300}, {"report": "session.json"}
]}
JSON
printf "| run | tets | iterations | view updates | update ms median / max | event-loop latency ms median / p95 / max |\n|---:|---:|---:|---:|---|---|\n"
for i in $(seq 1 "$runs"); do
  (cd "$work" && xvfb-run -a -s "-screen 0 1280x1024x24" "$studio" --script script.json > /dev/null 2>&1)
  python3 - "$work/session.json" "$i" <<'PY'
import json, sys
j = json.load(open(sys.argv[1])); l = j["event_loop_latency_ms"]; u = j["view_update_ms"]
print(f"| {sys.argv[2]} | {j['mesh']['tets']} | {j['iterations']} | {j['view_updates']} | {u['median']:.1f} / {u['max']:.1f} | {l['median']:.1f} / {l['p95']:.1f} / {l['max']:.1f} |")
PY
done
