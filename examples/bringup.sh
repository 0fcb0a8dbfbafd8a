#!/usr/bin/env bash
# A bring-up script, rehearsed on a simulated DG-5F right hand: one `sim serve` process plays
# the gripper, and every line below talks to it over TCP exactly as it would to the hardware.
# On the robot: drop the `sim serve` lines and set DELTOCTL_TARGET=tcp://169.254.186.72:502.
set -euo pipefail
deltoctl=${DELTOCTL:-deltoctl}
out=${OUT:-$(mktemp -d)}

"$deltoctl" sim serve dg-5f-right --json > "$out/sim.json" &
sim=$!
trap 'kill $sim 2>/dev/null' EXIT
for _ in $(seq 100); do [ -s "$out/sim.json" ] && break; sleep 0.05; done

export DELTOCTL_PROFILE=dg-5f-right
DELTOCTL_TARGET=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["endpoint"])' "$out/sim.json")
export DELTOCTL_TARGET

"$deltoctl" connect
"$deltoctl" identify
"$deltoctl" detect
"$deltoctl" home --yes
"$deltoctl" jog rj_dg_2_2 15deg --yes
"$deltoctl" jog rj_dg_2_2 -10deg --yes
"$deltoctl" calibrate ft --output-dir "$out" --yes
"$deltoctl" gpio set output_2 on --yes
"$deltoctl" gpio get
"$deltoctl" stream --duration 0.2 --interfaces 'rj_dg_2_*/position' | tail -n 1
"$deltoctl" record "$out/dg5f.mcap" --duration 2
echo "reports and recording in $out"
