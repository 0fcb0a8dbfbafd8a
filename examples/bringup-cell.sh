#!/usr/bin/env bash
# A bring-up script for a whole cell, rehearsed on its simulated devices: the Bioscara arm on
# I2C carrying a DG-3F-M gripper on TCP. One `sim serve` process plays both; every line below
# drives every block of the robot, each through its own transport, as on the real cell.
# On the robot: drop the `sim serve` lines and the targets; the profile names the links.
set -euo pipefail
deltoctl=${DELTOCTL:-deltoctl}
out=${OUT:-$(mktemp -d)}
mkdir -p "$out"
export DELTOCTL_PROFILE=bioscara-dg-3f-m

"$deltoctl" sim serve > "$out/targets.txt" &
sim=$!
trap 'kill $sim 2>/dev/null' EXIT
for _ in $(seq 100); do [ "$(wc -l < "$out/targets.txt")" -ge 2 ] && break; sleep 0.05; done
read -r -a targets <<< "$(tr '\n' ' ' < "$out/targets.txt")"  # --target BUS=URL, one per bus
dc() { "$deltoctl" "${targets[@]}" "$@"; }

dc connect                          # both blocks: lifecycle and round trips
dc identify                         # the arm's joints and flags; the gripper's model, firmware
dc detect                           # the I2C grid; the gripper's sensors and GPIO
dc home --yes                       # the arm into its hard stops, then the gripper to its pose
dc jog j4 -0.3 --yes                # an arm joint (I2C) ...
dc jog j_dg_1_2 10deg --yes         # ... and a gripper joint (TCP), found by name
dc gpio set gpio/output_2 on --yes  # grasp
dc stream --duration 0.2 --interfaces '*/connection_status' | tail -n 1
dc record "$out/cell.mcap" --duration 1
echo "recording in $out"
