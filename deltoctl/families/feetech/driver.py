"""A Feetech bus: ping and identify the profile's servos (model, firmware), register access
with the EEPROM lock around every EEPROM write, and two sync loops — present position,
velocity and load (56, 6) each cycle, voltage and temperature (62, 2) at 1 Hz — with their
communication statistics. Each servo's bytes are read in its own byte order and encodings
(models.py); a status error byte is a named fault with what to do. Positions are radians
around the middle of the turn, or LeRobot's calibration (calibration.py) when the block names
a ``calibration_file``. The wire is the servo kit's: the host session matches the replies,
the serial link tries and reopens by the exchange policy, the sync-read scheduler runs the
loops."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, ClassVar

from deltoctl.core.driver import Block, Driver, MoveResult, Progress
from deltoctl.core.exchange import ExchangePolicy
from deltoctl.core.loop import CommLoop
from deltoctl.errors import DeviceError, DeviceFault, InvalidInput, NoAnswer, Refused
from deltoctl.families.feetech import calibration, codec, parse_bus_url
from deltoctl.families.feetech.models import (
    BAUD_RATES,
    BUS_ITEMS,
    OPERATING_MODES,
    READINGS,
    Item,
    Model,
    by_bytes,
    expected_model,
    item_named,
    label,
)
from deltoctl.families.feetech.ros2_control import calibration_path, servo_ids, zero_steps
from deltoctl.servo.frames import Reply
from deltoctl.servo.serial_io import SerialLink
from deltoctl.servo.sync_loops import SyncLoops, SyncRead

POLICY = ExchangePolicy(tries=3, timeout=0.1, reopen_period=1.0)
REGISTER_POLICY = replace(POLICY, tries=5)
LOOPS = {"pvl_reader": 0.0, "tv_reader": 1.0}  # default Hz (0: every cycle)
NAN = float("nan")
GOAL, PRESENT, TORQUE = 42, 56, 40  # the same on every layout


def _modes(hw: Any) -> dict[str, str]:
    modes = {}
    for joint in hw.joints:
        mode = joint.params.get("norm_mode", calibration.DEGREES).strip().lower()
        if mode not in calibration.MODES:
            raise InvalidInput(f"{joint.name}: norm_mode {mode!r} is not one of "
                               f"{', '.join(calibration.MODES)}")
        modes[joint.name] = mode
    return modes


class FeetechDriver(Driver):
    def __init__(self, block: Block) -> None:
        super().__init__(block)
        parse_bus_url(self.url)  # a rate the servos cannot run: exit 2 before a port opens
        hw = block.hw
        self.joints = servo_ids(block.profile, hw)
        self.zero = {i: zero_steps(block.profile, hw, j) for i, j in self.joints.items()}
        path = calibration_path(block.profile, hw)
        self.calibration = calibration.load(path) if path is not None else {}
        self.modes = _modes(hw)
        self.session = codec.session()
        self.link = SerialLink(self.url, POLICY, self.stats)
        self.present: dict[int, tuple[Model, tuple[int, int]]] = {}  # id → model, firmware
        self.expected = {i: expected_model(hw.params, j.params, j.name)
                         for i, j in self.joints.items()}
        self.allow_model_mismatch = block.allow_model_mismatch
        self.moving: set[int] = set()
        self.faults: dict[int, int] = {}  # id → the error bits last warned of
        self._wrapping: dict[int, bool] = {}  # id → positions within one turn (Phase bit 4)
        self.loops = {}
        for name, default in LOOPS.items():
            try:
                rate = float(hw.params.get(f"{name}_rate", default))
            except ValueError:
                raise InvalidInput(f"{hw.name}: {name}_rate must be a number (Hz)") from None
            self.loops[name] = CommLoop(f"{hw.name}_{name}", rate)
        self.sync = SyncLoops(self.link, self.session, codec.SYNC_READ, self._lost)
        self.sync.add(SyncRead(self.loops["tv_reader"], 62, 2, self._take_voltage_temperature))
        self.sync.add(SyncRead(self.loops["pvl_reader"], PRESENT, 6, self._take_pvl))

    def comm_loops(self) -> list[CommLoop]:
        return list(self.loops.values())

    @property
    def port(self) -> Any:
        return self.link.port

    # -- faults ----------------------------------------------------------------------------------
    def _fault(self, device_id: int, error: int) -> None:
        """A status error byte seen in a read: a warning, once for each new fault."""
        if error and self.faults.get(device_id) != error:
            name = self.joints[device_id].name if device_id in self.joints else device_id
            self.warnings.append(f"{name} (ID {device_id}): "
                                 f"{', '.join(codec.error_names(error))} error — "
                                 f"{codec.error_advice(error)}")
        self.faults[device_id] = error

    # -- wire ------------------------------------------------------------------------------------
    def _request(self, device_id: int, instruction: int, params: bytes, what: str,
                 strict: bool = True) -> Reply:
        """One instruction and its status, tried while no valid reply comes. A status with
        an error byte is the servo's answer: a DeviceFault naming the fault and what to do
        (``strict``), or a warning when the data it brings is still good (a read)."""
        reply = self.link.request(self.session, device_id, instruction, params,
                                  f"{what} from servo {device_id} on {self.url}",
                                  REGISTER_POLICY)
        if reply[1] and strict:
            raise DeviceFault(f"servo {device_id} could not {what}: "
                              f"{', '.join(codec.error_names(reply[1]))} error",
                              code=reply[1], hint=codec.error_advice(reply[1]))
        self._fault(device_id, reply[1])
        return reply

    def ping(self, device_id: int) -> tuple[Model | None, tuple[int, int], bytes] | None:
        """A servo's model, firmware and model bytes (PING, then a READ of 0..4, as the
        SDK's ping), or None when it does not answer."""
        try:
            _, error, _ = self.link.request(self.session, device_id, codec.PING, b"",
                                            f"ping servo {device_id} on {self.url}")
        except NoAnswer:
            return None
        self._fault(device_id, error)
        data = self.read_bytes(device_id, 0, 5)
        return by_bytes(data[3:5]), (data[0], data[1]), bytes(data[3:5])

    def read_bytes(self, device_id: int, address: int, length: int) -> bytes:
        data = self._request(device_id, codec.READ, codec.read_params(address, length),
                             f"read {length} bytes at {address}", strict=False)[2]
        if len(data) != length:
            raise DeviceError(f"servo {device_id} sent {len(data)} bytes for {length}")
        return data

    def read_register(self, device_id: int, item: Item) -> int:
        return item.decode(self.read_bytes(device_id, item.address, item.size))

    def write_register_item(self, device_id: int, item: Item, value: int) -> None:
        """A write; an EEPROM item between Lock 0 and Lock 1, so the servo keeps it."""
        try:
            data = item.encode(value)
        except OverflowError:
            raise InvalidInput(f"{value} does not fit {item.name} ({item.size} byte(s), "
                               f"{item.encoding})") from None
        lock = self.model(device_id).lock
        if item.eeprom:
            self._write(device_id, lock, b"\x00", "unlock the EEPROM (Lock 0)")
        if item.name in ("ID", "Baud_Rate"):
            self._write_bus_item(device_id, item, value, data, lock)
            return
        try:
            self._write(device_id, item.address, data, f"write {item.name}")
        finally:
            if item.eeprom:
                self._write(device_id, lock, b"\x01", "lock the EEPROM (Lock 1)")

    def _write_bus_item(self, device_id: int, item: Item, value: int, data: bytes,
                        lock: int) -> None:
        """A new ID or baud rate: the servo answers this write from its old ID and rate, and
        at the new ones from then on, so the EEPROM is locked again there."""
        self.link.exchange(self.session, device_id, codec.WRITE,
                           codec.write_params(item.address, data), 0.05)
        baud = BAUD_RATES.get(value) if item.name == "Baud_Rate" else None
        new_id = value if item.name == "ID" else device_id
        own = self.port.baudrate if self.port is not None else None
        try:
            if baud is not None and own is not None:
                self.port.baudrate = baud
            self._write(new_id, lock, b"\x01", "lock the EEPROM (Lock 1)")
        finally:
            if own is not None:
                self.port.baudrate = own

    def _write(self, device_id: int, address: int, data: bytes, what: str) -> None:
        self._request(device_id, codec.WRITE, codec.write_params(address, data), what)

    def sync_write(self, address: int, data: dict[int, bytes]) -> None:
        length = len(next(iter(data.values())))
        self.link.write(codec.sync_write(address, length, data))
        self.stats["packets"] += 1

    # -- lifecycle -------------------------------------------------------------------------------
    def configure(self) -> None:
        self.link.open()
        for device_id in self.joints:
            found = self.ping(device_id)
            if found is not None:
                model, firmware, raw = found
                if model is None:
                    raise DeviceError(f"{self.joints[device_id].name} (ID {device_id}) reports "
                                      f"model bytes {raw.hex(' ')}, not a Feetech model "
                                      "deltoctl knows")
                self.present[device_id] = (model, firmware)
        self.roll_call([j.name for i, j in self.joints.items() if i not in self.present],
                       bool(self.present), "servo",
                       "check power, the cable between servos, the baud rate and the IDs "
                       "(deltoctl detect scans the other baud rates)")
        self._check_models()
        self.sync.singly = {i for i, (m, _) in self.present.items() if not m.sync_read}
        self.connected = True

    def _check_models(self) -> None:
        wrong = [f"{self.joints[i].name} (ID {i}) is {m.name}, the profile says "
                 f"{label(self.expected[i])}" for i, (m, _) in sorted(self.present.items())
                 if self.expected[i] is not None and m.number != self.expected[i]]
        if not wrong:
            return
        message = "model mismatch: " + "; ".join(wrong)
        if not self.allow_model_mismatch:
            raise DeviceError(message, hint="fix the profile's model param, or pass "
                              "--allow-model-mismatch to go on with the reported models")
        self.warnings.append(message + " (allowed; using each servo's own table)")

    def model(self, device_id: int) -> Model:
        return self.present[device_id][0]

    def identify(self) -> dict:
        """Each servo's model and firmware; servos of one bus on different firmware are a
        warning (LeRobot refuses such a bus)."""
        servos = {}
        for i, (m, (major, minor)) in sorted(self.present.items()):
            phase = self.read_register(i, m.by_name["Phase"])
            servos[self.joints[i].name] = {
                "id": i, "model_number": m.number, "model": m.name,
                "firmware": f"{major}.{minor}", "profile_model": self.expected[i],
                "model_match": self.expected[i] in (None, m.number),
                "byte_order": "big-endian" if m.big_endian else "little-endian",
                "full_angle_feedback": bool(phase & 0x10),
                "faults": codec.error_names(self.faults.get(i, 0))}
        versions = {s["firmware"] for s in servos.values()}
        if len(versions) > 1:
            which = ", ".join(f"{n} {s['firmware']}" for n, s in servos.items())
            self.warnings.append(f"{self.hw.name}: the servos run different firmware ({which}); "
                                 "LeRobot refuses such a bus: update them with Feetech's "
                                 "software (FD) to one version")
        return {"bus": self.url, "servos": servos}

    def round_trip(self) -> None:
        self.link.request(self.session, next(iter(self.present)), codec.PING, b"", "ping")

    def _lost(self, exc: Exception) -> None:
        if self.connected:
            self.warnings.append(f"{self.hw.name}: {self.url} lost ({exc})")
        self.connected = False
        self.link.lost()

    # -- positions -------------------------------------------------------------------------------
    def to_joint(self, device_id: int, raw: int) -> float:
        """A position in steps as the joint's value: radians (LeRobot's DEGREES mode with a
        calibration), or LeRobot's −100..100 or 0..100 in a range mode."""
        joint = self.joints[device_id]
        model = self.model(device_id)
        cal = self.calibration.get(joint.name)
        mode = self.modes[joint.name]
        if cal is not None:
            value = calibration.normalize(raw, cal, mode, model.resolution)
            return math.radians(value) if mode == calibration.DEGREES else value
        zero = self.zero.get(device_id)
        zero = model.resolution // 2 if zero is None else zero
        value = (raw - zero) * 2 * math.pi / model.resolution
        return (-value if joint.inverse else value) + joint.offset

    def to_steps(self, device_id: int, value: float) -> int:
        joint = self.joints[device_id]
        model = self.model(device_id)
        cal = self.calibration.get(joint.name)
        mode = self.modes[joint.name]
        if cal is not None:
            given = math.degrees(value) if mode == calibration.DEGREES else value
            return calibration.unnormalize(given, cal, mode, model.resolution)
        zero = self.zero.get(device_id)
        zero = model.resolution // 2 if zero is None else zero
        turn = (value - joint.offset) * (-1 if joint.inverse else 1)
        return round(turn * model.resolution / (2 * math.pi) + zero)

    # -- the sync loops --------------------------------------------------------------------------
    def start_read(self) -> None:
        if self.port is None and self.link.reopen():
            self.connected = True
        self.sync.start(list(self.present))

    def read(self) -> dict[str, float]:
        if not self.sync.pending:
            self.start_read()
        self.sync.finish()
        return self.values

    def _take_pvl(self, replies: list[Reply]) -> None:
        """Present Position, Velocity and Load (56, 6 bytes), in each servo's encodings."""
        values = self.values
        for device_id, error, data in replies:
            if device_id not in self.present:
                continue
            if error != self.faults.get(device_id, 0):
                self._fault(device_id, error)
            model = self.model(device_id)
            items = model.by_name
            name = self.joints[device_id].name
            values[name + "/position"] = self.to_joint(
                device_id, items["Present_Position"].decode(data, 0))
            # an inverse joint turns its velocity and effort with its position
            sign = -1 if self.joints[device_id].inverse and name not in self.calibration else 1
            steps_s = items["Present_Velocity"].decode(data, 2)
            values[name + "/velocity"] = sign * steps_s * 2 * math.pi / model.resolution
            values[name + "/effort"] = sign * items["Present_Load"].decode(data, 4) / 1000 \
                * model.stall_torque

    def _take_voltage_temperature(self, replies: list[Reply]) -> None:
        for device_id, _, data in replies:
            if device_id in self.joints:
                name = self.joints[device_id].name
                self.values[f"{name}/voltage"] = data[0] / 10.0
                self.values[f"{name}/temperature"] = float(data[1])

    # -- detect ----------------------------------------------------------------------------------
    def _broadcast_ping(self, timeout: float) -> list[int]:
        done = self.link.exchange(self.session, codec.BROADCAST_ID, codec.PING, b"", timeout)
        return sorted({i for i, _, _ in done.replies})

    def _models(self, ids: list[int]) -> dict[int, int | None]:
        """ID → model number, from one READ of 3..57 (model to present position): servos
        sharing an ID answer at once and their replies, which differ in position, garble
        (None)."""
        found: dict[int, int | None] = {}
        for i in ids:
            done = self.link.exchange(self.session, i, codec.READ, codec.read_params(3, 55))
            model = by_bytes(done.replies[0][2][:2]) if done.replies else None
            found[i] = model.number if model else None
        return found

    def detect(self) -> dict:
        """Broadcast ping at the bus's rate, the model of each servo that answers (a reply
        that garbles where the ping did not: two servos share the ID); when a servo is
        missing, broadcast pings at every other rate too."""
        assert self.port is not None
        found = self._models(self._broadcast_ping(0.3))
        collided = sorted(i for i, m in found.items() if m is None)
        expected = self.expected
        missing = sorted(set(expected) - set(found))
        elsewhere, unscanned = self._other_rates(found) if missing else ({}, {})
        unexpected = sorted(set(found) - set(expected))
        wrong = sorted(i for i in set(found) & set(expected)
                       if expected[i] is not None and found[i] not in (None, expected[i]))
        name = {i: j.name for i, j in self.joints.items()}
        checks = [self._servo_check(i, name.get(i), model, i in found, found.get(i),
                                    elsewhere.get(i)) for i, model in sorted(expected.items())]
        checks += [{"what": f"ID {i}", "profile": "no servo",
                    "device": label(found[i]) if found[i] else "replies collide",
                    "match": False} for i in unexpected]
        summary = (f"{self.hw.name}: {len(found)} servos answer ({len(missing)} missing, "
                   f"{len(unexpected)} unexpected)")
        if collided:
            summary += "; replies collide at ID " + ", ".join(map(str, collided)) + \
                " (two servos share it: give each its own ID, one servo connected at a time)"
        if elsewhere:
            summary += "; at another baud rate: " + ", ".join(
                f"{name.get(i, i)} ({baud})" for i, baud in sorted(elsewhere.items()))
        if unscanned:
            summary += "; not scanned: " + "; ".join(unscanned.values())
        return {"bus": self.url, "found": found, "missing": missing, "unexpected": unexpected,
                "wrong_model": wrong, "collided": collided,
                "wrong_baud": {str(i): b for i, b in elsewhere.items()},
                "unscanned": {str(b): why for b, why in unscanned.items()},
                "checks": checks, "summary": summary}

    def _servo_check(self, servo_id: int, joint: str | None, model: int | None,
                     answered: bool, answer: int | None, baud: int | None) -> dict:
        """A servo the profile declares, as the bus answers for it: its model, no answer, an
        answer at another baud rate only, or replies that collide (two servos at its ID)."""
        device = "no answer" if not answered else \
            label(answer) if answer is not None else "replies collide: two servos share the ID"
        if baud is not None:
            device = f"found at {baud} baud, not {self.port.baudrate}"
        return {"what": f"{joint or 'servo'} (ID {servo_id})", "part": joint,
                "profile": "a servo" if model is None else label(model), "device": device,
                "match": answer is not None and model in (None, answer),
                "missing": not answered}

    def _other_rates(self, found: dict[int, int | None]) -> tuple[dict[int, int], dict[int, str]]:
        from deltoctl.transport.serial_port import adapter_of_target

        adapter = adapter_of_target(self.url)
        unscanned = {}
        elsewhere: dict[int, int] = {}
        own = self.port.baudrate
        try:
            for baud in sorted(BAUD_RATES.values(), reverse=True):
                why = adapter.refuses(baud) if adapter is not None else None
                if baud == own or why:
                    if why:
                        unscanned[baud] = f"{baud} ({why})"
                    continue
                try:
                    self.port.baudrate = baud
                except (OSError, ValueError) as exc:
                    unscanned[baud] = f"{baud} ({exc})"
                    continue
                for i in self._broadcast_ping(max(0.05, 30 * 60 / baud)):
                    if i not in found:
                        elsewhere.setdefault(i, baud)
        finally:
            self.port.baudrate = own
        return elsewhere, unscanned

    # -- motion ----------------------------------------------------------------------------------
    def _goal_bytes(self, device_id: int, steps: int, speed: int) -> bytes:
        """Goal_Position, a Goal_Time (Running_Time on SCS) of 0, Goal_Velocity (42, 6)."""
        items = self.model(device_id).by_name
        position = items["Goal_Position"]
        low, high = position.span()
        return (position.encode(max(low, min(high, steps))) + bytes(2)
                + items["Goal_Velocity"].encode(max(1, min(32767, speed))))

    def send_goals(self, goals: dict[str, float], seconds: float) -> None:
        """Torque on, then each goal at the speed that takes ``seconds`` to reach it."""
        by_name = {j.name: i for i, j in self.joints.items() if i in self.present}
        ids = {by_name[n]: v for n, v in goals.items() if n in by_name}
        if not ids:
            return
        self._check_position_mode(list(ids))
        self.sync_write(TORQUE, {i: b"\x01" for i in ids})
        data = {}
        for i, value in ids.items():
            steps = self.to_steps(i, value)
            here = self.values.get(f"{self.joints[i].name}/position")
            start = self.to_steps(i, here) if here is not None else steps
            data[i] = self._goal_bytes(i, steps, round(abs(steps - start) / seconds))
        self.moving.update(ids)
        self.sync_write(GOAL, data)
        self.link.flush()

    def _check_position_mode(self, ids: list[int]) -> None:
        """Refused, before anything is written, when a servo to move is not in position mode
        (Operating_Mode 0): a goal position would not bring it there (an SCS has no such
        item: it runs to its goal)."""
        wrong = []
        for i in ids:
            item = self.model(i).by_name.get("Operating_Mode")
            mode = self.read_register(i, item) if item is not None else 0
            if mode:
                wrong.append(f"{self.joints[i].name} (Operating_Mode {mode}: "
                             f"{OPERATING_MODES.get(mode, 'unknown')})")
        if wrong:
            raise Refused(f"{', '.join(wrong)}: not in position mode (0), so a goal position "
                          "would not bring it there: nothing was moved",
                          hint="set it with deltoctl register set JOINT operating_mode 0, "
                               "then move again")

    def move(self, targets: dict[str, float], velocity: float | None = None,
             progress: Progress | None = None) -> MoveResult:
        import time

        from deltoctl.core.envelope import DEFAULT_TOLERANCE, DEFAULT_VELOCITY

        safety = self.profile.safety
        tolerance = safety.home_tolerance or DEFAULT_TOLERANCE
        timeout = safety.home_timeout or 5.0
        values = self.read()
        distance = max((abs(t - values.get(f"{j}/position", t)) for j, t in targets.items()),
                       default=0.0)
        seconds = max(0.1, distance / (velocity or DEFAULT_VELOCITY))
        self.send_goals(targets, seconds)
        hook = self.on_cycle
        setpoints = {j: (t, abs(t - values.get(f"{j}/position", t)) / seconds, NAN)
                     for j, t in targets.items()} if hook is not None else {}
        if hook is not None:
            hook(time.time_ns(), values, setpoints)
        start = time.monotonic()
        errors: dict[str, float] = {}
        while time.monotonic() - start < seconds + timeout and not self.halted.is_set():
            values = self.read()
            if hook is not None:
                hook(time.time_ns(), values, setpoints)
            errors = {j: abs(t - values.get(f"{j}/position", float("inf")))
                      for j, t in targets.items()}
            worst = max(errors.values(), default=0.0)
            if progress:
                progress(max(0.0, 1.0 - worst / (distance or 1.0)))
            # settled: within tolerance and stopped (the servo's own Present_Velocity)
            if worst <= tolerance and not any(values.get(f"{j}/velocity") for j in targets):
                self.moving.clear()
                return MoveResult(True, time.monotonic() - start, errors, [])
            self._latched(targets)
            time.sleep(0.02)
        return MoveResult(False, time.monotonic() - start, errors,
                          [j for j, e in errors.items() if e > tolerance])

    def _latched(self, joints: dict[str, float]) -> bool:
        """A servo to move that has latched its overload protection does not move until its
        power is cycled: a DeviceFault that says so, rather than a wait for the timeout."""
        latched = [self.joints[i].name for i, e in self.faults.items()
                   if e & 0x20 and self.joints[i].name in joints]
        if latched:
            raise DeviceFault(f"{', '.join(latched)}: overload protection latched, the servo "
                              "does not move", code=0x20, hint=codec.ERRORS[5][1])
        return False

    def set_torque(self, joints: list[str], on: bool) -> list[str]:
        ids = {i: j.name for i, j in self.joints.items() if j.name in joints and i in self.present}
        if ids:
            self.sync_write(TORQUE, {i: bytes([int(on)]) for i in ids})
            self.link.flush()
        return list(ids.values())

    def stop(self) -> None:
        """A move under way stops where it is (goal = present position); torque as found."""
        if not self.moving or self.port is None:
            return
        ids = sorted(self.moving)
        self.moving.clear()
        for _ in range(POLICY.tries):
            here = {i: data for i, _, data in self.sync.read(PRESENT, 2, ids)}
            if here:
                self.sync_write(GOAL, here)
                self.link.flush()
            ids = [i for i in ids if i not in here]
            if not ids:
                return
        self.warnings.append(f"{self.hw.name}: no present position from "
                             f"{', '.join(self.joints[i].name for i in ids)} to stop them at")

    # -- registers -------------------------------------------------------------------------------
    def servo(self, joint: str) -> int:
        for device_id, comp in self.joints.items():
            if comp.name == joint:
                if device_id not in self.present:
                    raise DeviceError(f"{joint} (ID {device_id}) does not answer on {self.url}")
                return device_id
        raise InvalidInput(f"{joint!r} is not a servo joint of {self.hw.name}")

    def read_registers(self, joint: str, items: list[str]) -> dict[str, Any]:
        device_id = self.servo(joint)
        model = self.model(device_id)
        chosen = [item_named(i, model) for i in items]
        if chosen:
            values = {i.name: self.read_register(device_id, i) for i in chosen}
        else:
            table = self.read_bytes(device_id, 0, model.table_size)
            chosen = list(model.table)
            values = {i.name: i.of_table(table) for i in chosen}
        return {"joint": joint, "id": device_id, "model": model.name, "items": [
            {"address": i.address, "item": i.name, "value": values[i.name],
             "access": ("EEPROM " if i.eeprom else "RAM ") + i.access} for i in chosen]}

    def write_register(self, joint: str, item: str, value: int) -> int:
        """Write one item (an EEPROM one between unlock and lock) and return what it reads
        back. A goal position or velocity is checked against the joint's envelope."""
        from deltoctl.core.envelope import check_command

        device_id = self.servo(joint)
        model = self.model(device_id)
        chosen = item_named(item, model)
        if chosen.access != "RW":
            raise InvalidInput(f"{chosen.name} is read-only")
        if not chosen.in_range(value):
            raise InvalidInput(f"{joint}: {chosen.name} {value} is outside the {model.name}'s "
                               f"documented range {chosen.low}..{chosen.high}")
        comp = self.joints[device_id]
        if chosen.name == "Goal_Position":
            self._check_calibrated_range(comp.name, value)
            here = self.read_register(device_id, model.by_name["Present_Position"])
            check_command(self.profile, comp, "position", self.to_joint(device_id, value),
                          self.to_joint(device_id, here))
        elif chosen.name == "Goal_Velocity":
            check_command(self.profile, comp, "velocity",
                          value * 2 * math.pi / model.resolution, None)
        self.write_register_item(device_id, chosen, value)
        if chosen.name in ("ID", "Baud_Rate"):
            return value  # it answers at its new ID or rate now
        return self.read_register(device_id, chosen)

    def _check_calibrated_range(self, joint: str, value: int) -> None:
        """A range mode clamps a raw goal into the calibration's range: a goal beyond it
        would pass the envelope as its bound while the servo goes elsewhere."""
        cal = self.calibration.get(joint)
        if cal is not None and self.modes[joint] != calibration.DEGREES and not (
                min(cal.range_min, cal.range_max) <= value
                <= max(cal.range_min, cal.range_max)):
            raise Refused(f"{joint}: Goal_Position {value} is outside the calibrated range "
                          f"{cal.range_min}..{cal.range_max}")

    # -- configuration ---------------------------------------------------------------------------
    def config_read(self) -> dict[str, dict[str, dict[str, Any]]]:
        parts = {}
        for device_id, joint in self.joints.items():
            if device_id not in self.present:
                continue
            model = self.model(device_id)
            table = self.read_bytes(device_id, 0, model.table_size)
            parts[joint.name] = {i.name: self._config_entry(i, i.of_table(table))
                                 for i in model.table}
        return parts

    @staticmethod
    def _config_entry(item: Item, value: int) -> dict[str, Any]:
        low, high = item.span()
        entry: dict[str, Any] = {"value": value, "access": item.access,
                                 "area": "EEPROM" if item.eeprom else "RAM",
                                 "address": item.address, "min": low, "max": high}
        if item.low is not None and item.high is not None:
            entry["low"], entry["high"] = item.low, item.high
        if item.unit:
            entry["unit"] = item.unit
        if item.sign_bit is not None:
            entry["note"] = f"sign-magnitude, sign in bit {item.sign_bit}"
        meaning = {"Baud_Rate": {c: f"{b} bps" for c, b in BAUD_RATES.items()},
                   "Operating_Mode": OPERATING_MODES}.get(item.name, {})
        if value in meaning:
            entry["meaning"] = meaning[value]
        if item.name in READINGS:
            entry["state"] = True
        elif item.name in BUS_ITEMS:
            entry["fixed"] = ("it changes how the servo answers on its bus: use deltoctl "
                              "register set")
        return entry

    def config_write(self, changes: dict[str, dict[str, Any]],
                     allow: frozenset[str] = frozenset()) -> dict[str, dict[str, Any]]:
        """Per servo, EEPROM items (unlocked, written, locked again) then RAM items, each in
        address order, then one read of the table."""
        plan = {self.servo(part): sorted(((self._restorable(part, name, value), value)
                                          for name, value in items.items()),
                                         key=lambda w: (not w[0].eeprom, w[0].address))
                for part, items in changes.items()}
        read_back = {}
        for device_id, writes in plan.items():
            for item, value in writes:
                self.write_register_item(device_id, item, value)
            model = self.model(device_id)
            table = self.read_bytes(device_id, 0, model.table_size)
            read_back[self.joints[device_id].name] = {
                item.name: item.of_table(table) for item, _ in writes}
        return read_back

    def _restorable(self, part: str, name: str, value: Any) -> Item:
        model = self.model(self.servo(part))
        item = model.by_name.get(name)
        if item is None or item.access != "RW" or name in READINGS or name in BUS_ITEMS:
            raise InvalidInput(f"{part}: {name!r} is not a control table item a restore writes")
        try:
            if isinstance(value, bool):
                raise TypeError
            item.encode(value)
        except (AttributeError, OverflowError, TypeError):
            raise InvalidInput(f"{part}: {name} takes an integer of {item.size} byte(s), "
                               f"{item.encoding}, not {value!r}") from None
        if (item.low is not None and value < item.low) or (item.high is not None
                                                           and value > item.high):
            raise InvalidInput(f"{part}: {name} {value} is outside the {model.name}'s "
                               f"documented range {item.low}..{item.high}")
        return item

    def make_safe(self) -> None:
        """Every servo of the block stops where it is (goal = present position), whatever
        this session moved; the torque stays on (an arm must not fall)."""
        self.moving.update(i for i in self.joints if i in self.present)
        self.stop()

    # -- LeRobot's calibration -------------------------------------------------------------------
    def lerobot_calibration(self) -> dict[str, calibration.MotorCalibration]:
        """The calibration the servos hold (Homing_Offset, Min/Max_Position_Limit, written
        by LeRobot's calibrate into EEPROM), as LeRobot's file has it; drive_mode 0, as
        LeRobot writes for the SO arms."""
        motors = {}
        for device_id, joint in self.joints.items():
            if device_id not in self.present:
                continue
            items = self.model(device_id).by_name
            offset = items.get("Homing_Offset")
            motors[joint.name] = calibration.MotorCalibration(
                id=device_id, drive_mode=0,
                homing_offset=self.read_register(device_id, offset) if offset else 0,
                range_min=self.read_register(device_id, items["Min_Position_Limit"]),
                range_max=self.read_register(device_id, items["Max_Position_Limit"]))
        return motors

    def half_turn_homing(self) -> None:
        """LeRobot's half-turn homing: each servo's offset set so that its present pose reads
        the middle of the turn (2047 on an STS3215), its position limits reset to the whole
        turn. Every new offset is checked before anything is written (torque off first)."""
        ids = [i for i in self.joints if i in self.present
               and "Homing_Offset" in self.model(i).by_name]
        offsets = {i: self._half_turn_offset(i) for i in ids}
        if not ids:
            return
        self.set_torque([self.joints[i].name for i in ids], False)
        for i, offset in offsets.items():
            items = self.model(i).by_name
            self.write_register_item(i, items["Homing_Offset"], offset)
            self.write_register_item(i, items["Min_Position_Limit"], 0)
            self.write_register_item(i, items["Max_Position_Limit"],
                                     self.model(i).resolution - 1)

    def _half_turn_offset(self, device_id: int) -> int:
        """The Homing_Offset that makes the present pose read mid-turn (present = actual −
        offset; within one turn unless Phase bit 4 asks for the full angle)."""
        model = self.model(device_id)
        items = model.by_name
        here = self.read_register(device_id, items["Present_Position"])
        actual = here + self.read_register(device_id, items["Homing_Offset"])
        if self._wraps(device_id):
            actual %= model.resolution
        offset = actual - (model.resolution - 1) // 2
        if abs(offset) > 2047:
            raise DeviceError(f"{self.joints[device_id].name}: its present position {actual} "
                              "is beyond the reach of Homing_Offset (±2047); nothing written",
                              hint="clear Phase bit 4 (positions in one turn), or cycle "
                                   "the servo's power, then calibrate again")
        return offset

    def calibrate_servos(self, half_turn: bool, name: str) -> dict[str, Any]:
        """LeRobot's calibration file of the servos (after its half-turn homing when asked),
        and where LeRobot looks for it: a leader's (a block whose joints take no command)
        under teleoperators/so_leader, a follower's under robots/so_follower."""
        if half_turn:
            self.half_turn_homing()
        motors = self.lerobot_calibration()
        leader = not any(j.command_interfaces for j in self.hw.joints)
        return {"format": "LeRobot calibration", "text": calibration.dump(motors),
                "file": str(calibration.default_path(name, leader)),
                "parts": {n: dict(vars(m)) for n, m in motors.items()}}

    # -- joint calibration (LeRobot's: present = actual − Homing_Offset) ----------------------
    calibration_registers: ClassVar[dict[str, str]] = {
        "homing_offset": "Homing_Offset", "range_min": "Min_Position_Limit",
        "range_max": "Max_Position_Limit"}
    lerobot_types = ("so_follower", "so_leader")

    def uncalibrated_joints(self) -> list[str]:
        """The servos without Homing_Offset (an SCS0009's table has none)."""
        return [j.name for i, j in self.joints.items()
                if i in self.present and "Homing_Offset" not in self.model(i).by_name]

    def joint_calibration(self) -> dict[str, dict[str, int]]:
        """LeRobot's calibration the servos hold (drive_mode 0, as LeRobot reads it)."""
        return {name: {**vars(m), "resolution": self.model(m.id).resolution}
                for name, m in self.lerobot_calibration().items()}

    def middle_offsets(self) -> dict[str, int]:
        return {self.joints[i].name: self._half_turn_offset(i) for i in self.joints
                if i in self.present and "Homing_Offset" in self.model(i).by_name}

    def _wraps(self, device_id: int) -> bool:
        """Positions within one turn (Phase bit 4 clear), read once per servo."""
        wraps = self._wrapping
        if device_id not in wraps:
            phase = self.read_register(device_id, self.model(device_id).by_name["Phase"])
            wraps[device_id] = not phase & 0x10
        return bool(wraps[device_id])

    def positions_under(self, offsets: dict[str, int],
                        held: dict[str, int]) -> dict[str, int]:
        ids = [i for i in self.joints if i in self.present]
        found = {}
        for device_id, _, data in self.sync.read(PRESENT, 2, ids):
            model = self.model(device_id)
            name = self.joints[device_id].name
            here = model.by_name["Present_Position"].decode(data) + held.get(name, 0) \
                - offsets.get(name, 0)
            found[name] = here % model.resolution if self._wraps(device_id) else here
        return found

    def write_joint_calibration(self, values: dict[str, dict[str, int]]) -> None:
        """Torque off, then Homing_Offset and the position limits, each between the EEPROM's
        unlock and lock."""
        self.set_torque(list(values), False)
        for joint, entry in values.items():
            device_id = self.servo(joint)
            items = self.model(device_id).by_name
            for key in ("homing_offset", "range_min", "range_max"):
                self.write_register_item(device_id, items[self.calibration_registers[key]],
                                         entry[key])

    def cleanup(self) -> None:
        self.link.close()
        self.connected = False
