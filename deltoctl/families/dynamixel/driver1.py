"""A Dynamixel Protocol 1.0 bus (AX, RX, MX servos): the verbs of the Protocol 2.0 driver over
the Protocol 1.0 session. Protocol 1.0 has no SYNC_READ and no broadcast PING: each cycle reads
Present Position, Speed, Load, Voltage and Temperature (36, 8 bytes) of each servo in turn, or
of a bus of MX servos in one BULK_READ; goals and torque go out in SYNC_WRITEs. A joint's zero
is its servo's middle step (512 of 0-1023 over 300°, 2048 of 0-4095 over 360°); a reversed
joint is reversed here (Protocol 1.0 servos have no Drive Mode)."""

from __future__ import annotations

import struct
from typing import Any, ClassVar

from deltoctl.core.driver import Block, Driver
from deltoctl.core.loop import CommLoop
from deltoctl.errors import DeviceError, DeviceFault, InvalidInput, LinkLost, NoAnswer, Refused
from deltoctl.families.dynamixel import parse_bus_url
from deltoctl.families.dynamixel import protocol1 as p1
from deltoctl.families.dynamixel.driver import POLICY, REGISTER_POLICY, DynamixelDriver
from deltoctl.families.dynamixel.models import expected_model
from deltoctl.families.dynamixel.models1 import (
    GOAL_POSITION,
    PRESENT,
    TORQUE_ENABLE,
    Model1,
    baud_of,
)
from deltoctl.families.dynamixel.ros2_control import servo_ids
from deltoctl.servo.frames import Reply
from deltoctl.servo.serial_io import SerialLink

PRESENT_STRUCT = struct.Struct("<HHHBB")  # position, speed, load, voltage, temperature
SIGN = 1 << 10
MOVING = 46  # 1 while the servo runs to its goal
SCAN_BAUDS_1 = (1_000_000, 57_600, 115_200, 500_000, 400_000, 250_000, 200_000, 19_200, 9_600)


def _signed(raw: int) -> int:
    """A sign-magnitude reading (speed, load): bit 10 set is clockwise, negative."""
    return -(raw & 0x3FF) if raw & SIGN else raw & 0x3FF


class Protocol1Driver(DynamixelDriver):
    protocol = 1.0
    # no Homing Offset in a Protocol 1.0 table: no joint calibration (the contract's refusal)
    calibration_registers: ClassVar[dict[str, str]] = {}
    lerobot_types = None
    joint_calibration = Driver.joint_calibration
    middle_offsets = Driver.middle_offsets
    positions_under = Driver.positions_under
    write_joint_calibration = Driver.write_joint_calibration

    def __init__(self, block: Block) -> None:  # the 2.0 driver's attributes, no sync loops
        Driver.__init__(self, block)
        parse_bus_url(self.url, 1.0)
        hw = block.hw
        self.joints = servo_ids(block.profile, hw)
        self.gpio_states: dict[int, dict[str, str]] = {}
        self.session = p1.session()
        self.link = SerialLink(self.url, POLICY, self.stats)
        self.present: dict[int, tuple[int, int]] = {}
        self.expected = {i: expected_model(hw.params, j.params, j.name)
                         for i, j in self.joints.items()}
        self.allow_model_mismatch = block.allow_model_mismatch
        self.torque_enabled: set[int] = set()
        self.moving: set[int] = set()
        self.fast = False
        self._followed: dict[str, tuple[float, float]] = {}
        self._units = None
        self.loops = {}
        for name in ("pvl_reader", "pv_writer", "t_writer"):
            try:
                rate = float(hw.params.get(f"{name}_rate", 0.0))
            except ValueError:
                raise InvalidInput(f"{hw.name}: {name}_rate must be a number (Hz)") from None
            self.loops[name] = CommLoop(f"{hw.name}_{name}", rate if "reader" in name else 0.0)
        self._pending = False

    def configure(self) -> None:
        from deltoctl import trace

        if trace.PACKETS:  # -vv: this link's frames are Protocol 1.0's, not the family's 2.0
            trace.name_frames(self.url, p1.frame_name)
        super().configure()

    # -- wire ------------------------------------------------------------------------------------
    def ping(self, device_id: int) -> tuple[int, int] | None:
        """(model number, firmware): a PING, then the two read at address 0 (a Protocol 1.0
        PING's status holds no data)."""
        try:
            self.link.request(self.session, device_id, p1.PING, b"",
                              f"ping servo {device_id} on {self.url}")
        except NoAnswer:
            return None
        model, firmware = struct.unpack("<HB", self.read_table(device_id, 0, 3))
        return model, firmware

    def _request(self, device_id: int, instruction: int, params: bytes, what: str) -> Reply:
        reply = self.link.request(self.session, device_id, instruction, params,
                                  f"{what} from servo {device_id} on {self.url}",
                                  REGISTER_POLICY)
        if reply[1]:
            raise DeviceFault(f"servo {device_id} refused to {what}: "
                              f"{p1.error_text(reply[1])}", code=reply[1],
                              hint=p1.error_hint(reply[1]) or None)
        return reply

    def read_table(self, device_id: int, address: int = 0, length: int = 50) -> bytes:
        return self._request(device_id, p1.READ, p1.read_params(address, length),
                             f"read {length} bytes at {address}")[2]

    def write_register_item(self, device_id: int, item: Any, value: int) -> None:
        try:
            data = item.encode(value)
        except OverflowError:
            raise InvalidInput(f"{value} does not fit {item.name} ({item.size} byte(s))") \
                from None
        self._request(device_id, p1.WRITE, p1.write_params(item.address, data),
                      f"write {item.name}")

    def model(self, device_id: int) -> Model1:  # type: ignore[override]
        from deltoctl.families.dynamixel.models import by_number

        number = self.present[device_id][0]
        model = by_number(number)
        if not isinstance(model, Model1):
            raise DeviceError(f"{self.joints[device_id].name} (ID {device_id}) reports model "
                              f"number {number}, not a Protocol 1.0 model deltoctl knows")
        return model

    def _check_models(self) -> None:
        """The 2.0 driver's check, then a servo of a model deltoctl has no Protocol 1.0 table
        for is refused, whatever is allowed: its steps' scale (300° in 1,024 or 360° in
        4,096) is not known, so no position of it could be read or sent."""
        from deltoctl.families.dynamixel.models import by_number
        from deltoctl.families.dynamixel.models1 import MODELS_1

        super()._check_models()
        unknown = [f"{self.joints[i].name} (ID {i}) reports model number {m}"
                   for i, (m, _) in sorted(self.present.items())
                   if not isinstance(by_number(m), Model1)]
        if unknown:
            raise DeviceError("; ".join(unknown) + ": not a Protocol 1.0 model deltoctl knows",
                              hint="deltoctl knows " + ", ".join(m.name for m in MODELS_1))

    # -- the read loop: each servo in turn, or an MX bus in one BULK_READ ------------------------
    def start_read(self) -> None:
        if self.port is None and self.link.reopen():
            self.connected = True

    def read(self) -> dict[str, float]:
        self.start_read()
        loop = self.loops["pvl_reader"]
        if self.port is None or not self.present or not loop.due():
            return self.values
        ids = list(self.present)
        try:
            replies = self.read_present(ids)
        except (OSError, LinkLost) as exc:  # pyserial's errors are OSErrors too
            self._lost(exc)
            return self.values
        loop.count(len(replies) == len(ids))
        self._take_present(replies)
        return self.values

    def read_present(self, ids: list[int]) -> list[Reply]:
        """Present Position to Temperature (36, 8 bytes) of each servo: one BULK_READ when
        every one is an MX, else a READ of each in turn."""
        if all(self.model(i).bulk_read for i in ids):
            return self.bulk_read([(i, *PRESENT) for i in ids])
        replies = []
        params = p1.read_params(*PRESENT)
        for i in ids:
            self.stats["packets"] += 1
            done = self.link.exchange(self.session, i, p1.READ, params)
            self.stats["errors"] += not done.complete
            replies += done.replies
        return replies

    def bulk_read(self, reads: list[tuple[int, int, int]]) -> list[Reply]:
        self.stats["packets"] += 1
        done = self.link.exchange(self.session, p1.BROADCAST_ID, p1.BULK_READ,
                                  p1.bulk_read_params(reads))
        self.stats["errors"] += not done.complete
        return done.replies

    def _take_present(self, replies: list[Reply]) -> None:
        values = self.values
        for device_id, error, data in replies:
            if error or len(data) != PRESENT[1]:
                continue
            model = self.model(device_id)
            joint = self.joints[device_id]
            position, speed, load, voltage, temperature = PRESENT_STRUCT.unpack(data)
            sign = -1.0 if joint.inverse else 1.0
            name = joint.name
            values[name + "/position"] = sign * (position - model.center) * model.rad_per_step \
                + joint.offset
            values[name + "/velocity"] = sign * _signed(speed) * model.rad_s_per_unit
            values[name + "/effort"] = sign * _signed(load) / 1000.0  # of the max torque
            values[name + "/voltage"] = voltage / 10.0
            values[name + "/temperature"] = float(temperature)

    def _raw_goal(self, device_id: int, rad: float) -> int:
        model = self.model(device_id)
        joint = self.joints[device_id]
        sign = -1.0 if joint.inverse else 1.0
        return round(sign * (rad - joint.offset) / model.rad_per_step + model.center)

    # -- commands --------------------------------------------------------------------------------
    def send_goals(self, goals: dict[str, float], seconds: float) -> None:
        """Torque on, then Goal Position and Moving Speed (30, 4) of each servo in one
        SYNC_WRITE: each joint arrives in ``seconds``."""
        by_name = {j.name: i for i, j in self.joints.items() if i in self.present}
        ids = {by_name[name]: rad for name, rad in goals.items() if name in by_name}
        if not ids:
            return
        data = {}
        for i, rad in ids.items():
            model = self.model(i)
            now = self.values.get(f"{self.joints[i].name}/position", rad)
            speed = min(1023, max(1, round(abs(rad - now) / seconds / model.rad_s_per_unit)))
            goal, reach = self._raw_goal(i, rad), model.by_name["Goal Position"]
            if not reach.in_range(goal):
                raise Refused(f"{self.joints[i].name}: {rad:.4f} rad is step {goal}, beyond "
                              f"the {model.name}'s Goal Position {reach.low}..{reach.high}",
                              hint="bring the joint's limits in the profile within the "
                                   "servo's reach")
            data[i] = struct.pack("<HH", goal, speed)
        self._torque(list(ids), True)
        self.moving.update(ids)
        self.link.write(p1.sync_write(GOAL_POSITION, 4, data))
        self.link.flush()
        self.loops["pv_writer"].count(True)
        self.stats["packets"] += 2

    def _stopped(self, joints: list[str]) -> set[str]:
        """The joints whose servo says it stopped (Moving, 46, reads 0), each read in turn (no
        Sync Read in 1.0); a servo that does not answer is not known to have stopped."""
        if self.port is None:
            return set()
        stopped = set()
        for i, c in self.joints.items():
            if c.name in joints and i in self.present:
                try:
                    if self.read_table(i, MOVING, 1) == b"\x00":
                        stopped.add(c.name)
                except DeviceError:
                    continue
        return stopped

    def _torque(self, ids: list[int], on: bool) -> None:
        self.link.write(p1.sync_write(TORQUE_ENABLE, 1, {i: bytes([int(on)]) for i in ids}))
        self.loops["t_writer"].count(True)
        self.stats["packets"] += 1
        if on:
            self.torque_enabled.update(ids)
        else:
            self.torque_enabled.difference_update(ids)

    def reboot(self, joints: list[str]) -> list[str]:
        raise DeviceError(f"{self.hw.name}: Protocol 1.0 servos have no REBOOT instruction",
                          hint="power-cycle the bus to clear a shutdown")

    def stop(self) -> None:
        """A move under way stops where each servo is (goal = present position)."""
        if not self.moving or self.port is None:
            return
        here = {}
        for i in sorted(self.moving):
            done = self.link.exchange(self.session, i, p1.READ, p1.read_params(36, 2))
            if done.replies and not done.replies[0][1]:
                here[i] = done.replies[0][2]
        self.moving.clear()
        if here:
            self.link.write(p1.sync_write(GOAL_POSITION, 2, here))
            self.link.flush()

    def _check_goal(self, device_id: int, item: str, raw: int) -> None:
        """A Goal Position or Moving Speed against the joint's envelope; the angle limits
        (both 0: wheel mode) only through ``config restore --allow``."""
        from deltoctl.core.envelope import check_command

        model = self.model(device_id)
        joint = self.joints[device_id]
        if item in ("CW Angle Limit", "CCW Angle Limit"):
            key = item.lower().replace(" ", "-")
            raise Refused(f"{joint.name}: {item} is a safety setting (0 and 0: wheel mode)",
                          hint=f"write it with deltoctl config restore --allow {key}")
        if item == "Moving Speed":  # 0: the servo's greatest speed, uncontrolled
            check_command(self.profile, joint, "velocity",
                          (abs(raw) or 1023) * model.rad_s_per_unit, None)
        if item != "Goal Position":
            return
        here = self.read_register(device_id, model.by_name["Present Position"])
        sign = -1.0 if joint.inverse else 1.0

        def rad(step: int) -> float:
            return sign * (step - model.center) * model.rad_per_step + joint.offset

        check_command(self.profile, joint, "position", rad(raw), rad(here))

    # -- configuration ---------------------------------------------------------------------------
    def _config_entry(self, item: Any, values: dict[str, int],  # type: ignore[override]
                      model: Any) -> dict[str, Any]:
        entry = DynamixelDriver._config_entry(item, values, model)
        entry.pop("needs", None)  # Protocol 1.0 EEPROM takes writes with torque on
        entry.pop("meaning", None)
        if item.name == "Baud Rate":
            entry["meaning"] = f"{baud_of(values[item.name])} bps"
        return entry

    def config_write(self, changes: dict[str, dict[str, Any]],
                     allow: frozenset[str] = frozenset()) -> dict[str, dict[str, Any]]:
        """Per servo, each item in address order (all checked first), then one read back."""
        plan = {self.servo(part): sorted(((self._restorable(part, name, value), value)
                                          for name, value in items.items()),
                                         key=lambda w: w[0].address)
                for part, items in changes.items()}
        read_back = {}
        for device_id, writes in plan.items():
            for item, value in writes:
                self.write_register_item(device_id, item, value)
            model = self.model(device_id)
            table = self.read_table(device_id, 0, model.table_size)
            read_back[self.joints[device_id].name] = {
                item.name: item.of_table(table) for item, _ in writes}
        return read_back

    # -- detect ----------------------------------------------------------------------------------
    def detect(self) -> dict:
        """A PING of each of the profile's IDs (Protocol 1.0 has no broadcast PING); for the
        missing, pings at the other Protocol 1.0 rates, then a Protocol 2.0 broadcast PING.
        The block's ``detect_sweep: true`` pings every other ID too, at the bus's rate (a few
        seconds), to find servos at IDs the profile does not list."""
        from deltoctl.families.dynamixel.driver import other_protocol

        assert self.port is not None
        sweep = self._sweep_asked()
        found = {}
        for i in self.expected:
            answer = self.ping(i)
            if answer is not None:
                found[i] = answer[0]
        if sweep:
            for i in range(p1.BROADCAST_ID):
                if i not in self.expected and self._quick_ping(i):
                    answer = self.ping(i)
                    if answer is not None:
                        found[i] = answer[0]
        missing = sorted(set(self.expected) - set(found))
        elsewhere: dict[int, int] = {}
        own = self.port.baudrate
        if missing:
            try:
                for baud in SCAN_BAUDS_1:
                    if baud != own and len(elsewhere) < len(missing):
                        self.port.baudrate = baud
                        for i in missing:
                            if i not in elsewhere and self._quick_ping(i):
                                elsewhere[i] = baud
            finally:
                self.port.baudrate = own
        speaks_2 = other_protocol(self, [i for i in missing if i not in elsewhere], 1.0)
        report = self._detect_report(found, missing, elsewhere, speaks_2)
        report["swept"] = sweep
        if not sweep:
            report["summary"] += ("; other IDs not looked for (no broadcast PING in Protocol "
                                  "1.0: the block's detect_sweep param, or deltoctl scan, "
                                  "pings every ID)")
        return report

    def _sweep_asked(self) -> bool:
        value = str(self.hw.params.get("detect_sweep", "false")).strip().lower()
        if value not in ("true", "false"):
            raise InvalidInput(f"{self.hw.name}: detect_sweep is true or false, not {value!r}")
        return value == "true"

    def _quick_ping(self, device_id: int) -> bool:
        done = self.link.exchange(self.session, device_id, p1.PING, b"", 0.02)
        return bool(done.replies)

