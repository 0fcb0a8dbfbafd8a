#!/usr/bin/env bash
# A bring-up script for the Bioscara SCARA arm, rehearsed on its simulated I2C bus: one
# `sim serve` process plays the four uStepper joints, and every line below talks to them
# through the I2C transport exactly as it would on the Raspberry Pi.
# On the robot: drop the `sim serve` lines; the profile's bus is i2c:///dev/i2c-1.
set -euo pipefail
deltoctl=${DELTOCTL:-deltoctl}
out=${OUT:-$(mktemp -d)}

"$deltoctl" sim serve bioscara-arm --json > "$out/sim.json" &
sim=$!
trap 'kill $sim 2>/dev/null' EXIT
for _ in $(seq 100); do [ -s "$out/sim.json" ] && break; sleep 0.05; done

export DELTOCTL_PROFILE=bioscara-arm
DELTOCTL_TARGET=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["buses"]["i2c"])' "$out/sim.json")
export DELTOCTL_TARGET

"$deltoctl" connect
"$deltoctl" detect
"$deltoctl" identify
if "$deltoctl" jog j4 -0.1 --yes; then  # a joint moves only once homed
    echo "jog before homing should have been refused" >&2
    exit 1
fi
"$deltoctl" home --yes                  # j2, j1, j4, j3: each into its hard stop
"$deltoctl" jog j4 -0.3 --yes
"$deltoctl" jog j2 -0.02 --velocity 0.01 --yes
"$deltoctl" stream --duration 0.2 --interfaces 'j*/position' | tail -n 1
"$deltoctl" record "$out/bioscara.mcap" --duration 1
echo "recording in $out"
