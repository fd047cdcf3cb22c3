#!/usr/bin/env bash
# The TurtleBot3's random walk as a live twin (make demo): a perturbed TurtleBot served over OPC UA by
# `cotwin plant` as the PT, the embedded simulator as the DT, both running the d-model with the same seed;
# no commands (the robot is autonomous). Writes OUT/{pt,dt}/outputs.csv, deviation.json, figure.png.
set -euo pipefail
COTWIN=${COTWIN:-.venv/bin/cotwin}
PROJECT=${PROJECT:-examples/turtlebot/live.toml}
OUT=${1:-out/demo/turtlebot-twin}
mkdir -p "$OUT"
pids=()
cleanup() { for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap cleanup EXIT

# on a free port (port 0: the plant says which), so that other plants on this machine are left alone
"$COTWIN" plant "$PROJECT" --opcua opc.tcp://127.0.0.1:0 > "$OUT/plant.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 60); do grep -q "^serving" "$OUT/plant.log" 2>/dev/null && break; sleep 0.5; done
grep -q "^serving" "$OUT/plant.log" || { cat "$OUT/plant.log"; echo "the plant did not start" >&2; exit 1; }
url=$(sed -n 's|^serving .* on \(opc\.tcp://[^ ]*\) .*|\1|p' "$OUT/plant.log" | head -n 1)

"$COTWIN" twin "$PROJECT" -o "$OUT" --pt-url "$url" 2> "$OUT/twin.log"
echo "live twin of the walk: $OUT/figure.png, $OUT/deviation.json, $OUT/pt/outputs.csv, $OUT/dt/outputs.csv"
