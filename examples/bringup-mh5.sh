#!/usr/bin/env bash
# A bring-up script for the MH5 humanoid, rehearsed on its simulated buses: one `sim serve`
# process plays both RS-485 servo buses (pseudo-terminals) and the I2C bus with the IMU, and
# every line below talks to them through pyserial and the I2C transport as on the robot.
# On the robot: drop the `sim serve` lines and the -t options; the profile names the ports.
set -euo pipefail
deltoctl=${DELTOCTL:-deltoctl}
out=${OUT:-$(mktemp -d)}

"$deltoctl" sim serve mh5 --json > "$out/sim.json" &
sim=$!
trap 'kill $sim 2>/dev/null' EXIT
for _ in $(seq 100); do [ -s "$out/sim.json" ] && break; sleep 0.05; done

export DELTOCTL_PROFILE=mh5
mapfile -t targets < <(python3 -c 'import json,sys
for bus, url in json.load(open(sys.argv[1]))["buses"].items(): print(f"-t\n{bus}={url}")' "$out/sim.json")

"$deltoctl" "${targets[@]}" connect
"$deltoctl" "${targets[@]}" detect                        # 22 servos and the IMU
"$deltoctl" "${targets[@]}" register get head_y present_temperature present_input_voltage
"$deltoctl" "${targets[@]}" register set head_y return_delay_time 0 --yes
"$deltoctl" "${targets[@]}" jog head_y 15deg --velocity 30deg --yes   # torque comes on
"$deltoctl" "${targets[@]}" home --yes
"$deltoctl" "${targets[@]}" torque off legs --yes
"$deltoctl" "${targets[@]}" stream --duration 0.2 --interfaces 'imu/linear_acceleration.*' | tail -n 1
"$deltoctl" "${targets[@]}" record "$out/mh5.mcap" --duration 1.5
echo "recording in $out"
