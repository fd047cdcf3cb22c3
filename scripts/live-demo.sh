#!/usr/bin/env bash
# The live twin end to end (make demo): a perturbed robot cell served over OPC UA as the PT, the
# embedded MuJoCo twin as the DT, and the paper's four commands published live to RabbitMQ by a
# publisher that follows the RMQ FMU protocol. Writes OUT/{pt,dt}/outputs.csv, deviation.json,
# figure.png and history.sqlite. Needs RabbitMQ on 127.0.0.1:5672.
set -euo pipefail
COTWIN=${COTWIN:-.venv/bin/cotwin}
PROJECT=${PROJECT:-examples/ur5e/twin.toml}
OUT=${1:-out/demo/twin}
EXCHANGE=cotwin_demo_$$
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

"$COTWIN" publish "$PROJECT" --exchange "$EXCHANGE" > "$OUT/publisher.log" 2>&1 &
pids+=($!)
"$COTWIN" twin "$PROJECT" -o "$OUT" --pt-url "$url" --rabbitmq "$EXCHANGE" 2> "$OUT/twin.log"
echo "live twin: $OUT/figure.png, $OUT/deviation.json, $OUT/pt/outputs.csv, $OUT/dt/outputs.csv (log: $OUT/twin.log)"
