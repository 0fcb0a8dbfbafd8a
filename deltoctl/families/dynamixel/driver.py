"""A Dynamixel Protocol 2.0 bus: ping and identify the profile's servos, register access with
retries, and the MH5's sync loops — present load/velocity/position read (126, 10), voltage and
temperature read (144, 3), profile/goal write (108, 12), torque write (64) — each at its own
rate (the block's ``<loop>_rate`` params) with its own communication statistics. The wire is
the servo kit's: the host session matches the replies, the serial link tries and reopens by
the exchange policy, the sync-read scheduler runs the loops."""

from __future__ import annotations

import struct
from dataclasses import replace
from typing import Any, ClassVar

from deltoctl.core.driver import Block, Driver, MoveResult, Progress
from deltoctl.core.exchange import ExchangePolicy
from deltoctl.core.loop import CommLoop
from deltoctl.errors import DeviceError, DeviceFault, InvalidInput, NoAnswer, Refused
from deltoctl.families.dynamixel import codec, parse_bus_url
from deltoctl.families.dynamixel.control_table import (
    BAUD_RATES,
    BY_NAME,
    TABLE_SIZE,
    Item,
)
from deltoctl.families.dynamixel.models import Model, by_number, expected_model, label
from deltoctl.families.dynamixel.ros2_control import gpio_readings, servo_ids
from deltoctl.servo.frames import Reply
from deltoctl.servo.serial_io import SerialLink
from deltoctl.servo.sync_loops import SyncLoops, SyncRead

RAD_PER_RAW = 0.001533980787886  # 2π/4096
CENTER = 2047
RAD_S_PER_RAW = 0.023980823922402  # 0.229 rpm
DRIVE_MODE = BY_NAME["Drive Mode"]
MOVING = BY_NAME["Moving"]
PVL = struct.Struct("<hii")  # Present Load, Velocity, Position (126, 10 bytes)
LOAD_SCALE = 0.0014
# 3 tries of 100 ms; a lost port reopened once a second
POLICY = ExchangePolicy(tries=3, timeout=0.1, reopen_period=1.0)
REGISTER_POLICY = replace(POLICY, tries=5)  # as the MH5's register helpers
SCAN_BAUDS = sorted(BAUD_RATES.values(), key=lambda b: (b < 57600, b))  # 9600 last: slowest
NAN = float("nan")
LOOPS = {"pvl_reader": 0.0, "tv_reader": 1.0, "pv_writer": 0.0, "t_writer": 0.0}  # default Hz


def refused_rates(url: str, bauds: list[int]) -> dict[int, str]:
    """The rates of ``bauds`` the bus's adapter cannot set (its driver's), each with why:
    a scan leaves them out rather than fail in the middle."""
    from deltoctl.transport.serial_port import adapter_of_target

    adapter = adapter_of_target(url)
    why = {b: adapter.refuses(b) for b in bauds} if adapter is not None else {}
    return {b: f"{b} ({reason})" for b, reason in why.items() if reason}


def _amps_per_step(number: int) -> float | None:
    model = by_number(number)
    return None if model is None or model.current_unit is None else model.current_unit / 1000


def other_protocol(driver: DynamixelDriver, ids: list[int], own: float) -> list[int]:
    """Which of ``ids`` answer in the other protocol than the bus's ``own``, at its rate: a
    Protocol 1.0 PING of each, or one Protocol 2.0 broadcast PING."""
    if not ids or driver.port is None:
        return []
    if own == 2.0:
        from deltoctl.families.dynamixel import protocol1

        session = protocol1.session()
        return [i for i in ids if driver.link.exchange(session, i, protocol1.PING, b"",
                                                       0.05).replies]
    done = driver.link.exchange(codec.session(), codec.BROADCAST_ID, codec.PING, b"", 0.1)
    return sorted({r[0] for r in done.replies} & set(ids))


class DynamixelDriver(Driver):
    protocol = 2.0

    def __init__(self, block: Block) -> None:
        super().__init__(block)
        parse_bus_url(self.url)  # a rate its servos cannot run: exit 2 before a port opens
        hw = block.hw
        self.joints = servo_ids(block.profile, hw)
        # dynamixel_hardware_interface's servo gpios: their Present ... states, by servo
        self.gpio_states = gpio_readings(block.profile, hw)
        self.session = codec.session()
        self.link = SerialLink(self.url, POLICY, self.stats)
        self.present: dict[int, tuple[int, int]] = {}  # id → (model, firmware)
        self.expected = {i: expected_model(hw.params, j.params, j.name)
                         for i, j in self.joints.items()}
        self.allow_model_mismatch = block.allow_model_mismatch
        self.torque_enabled: set[int] = set()
        self.moving: set[int] = set()  # servos sent a goal they may not have reached
        # Fast Sync Read (XL430 firmware 45 and later) for the reader loops, when the block
        # says fast_sync_read: true
        self.fast = str(hw.params.get("fast_sync_read", "false")).lower() in ("1", "true", "yes")
        self._followed: dict[str, tuple[float, float]] = {}  # replayed goals and speeds
        self._units: dict[int, float | None] | None = None  # Present Current's A per step
        self.loops = {}
        for name, default in LOOPS.items():
            try:
                rate = float(hw.params.get(f"{name}_rate", default))
            except ValueError:
                raise InvalidInput(f"{hw.name}: {name}_rate must be a number (Hz)") from None
            # writers send what a verb commands, when it commands it: never held back
            self.loops[name] = CommLoop(f"{hw.name}_{name}", rate if "reader" in name else 0.0)
        self.sync = SyncLoops(self.link, self.session,
                              codec.FAST_SYNC_READ if self.fast else codec.SYNC_READ, self._lost)
        # the slow loop's exchange in full, then the fast loop's, overlapped with other buses'
        self.sync.add(SyncRead(self.loops["tv_reader"], 144, 3, self._take_voltage_temperature))
        self.sync.add(SyncRead(self.loops["pvl_reader"], 126, 10, self._take_pvl))

    def comm_loops(self) -> list[CommLoop]:
        return list(self.loops.values())

    # -- wire ------------------------------------------------------------------------------------
    @property
    def port(self) -> Any:
        """The bus's serial port (None while it is lost)."""
        return self.link.port

    def ping(self, device_id: int) -> tuple[int, int] | None:
        """(model number, firmware) of a servo, or None when it does not answer."""
        try:
            _, _, data = self.link.request(self.session, device_id, codec.PING, b"",
                                           f"ping servo {device_id} on {self.url}")
        except NoAnswer:
            return None
        model, firmware = struct.unpack_from("<HB", data)
        return model, firmware

    # -- registers -------------------------------------------------------------------------------
    def _request(self, device_id: int, instruction: int, params: bytes, what: str) -> Reply:
        """One instruction and its status, tried up to 5 times while no valid reply comes;
        a status with an error is the servo's answer (DeviceFault), not tried again."""
        reply = self.link.request(self.session, device_id, instruction, params,
                                  f"{what} from servo {device_id} on {self.url}",
                                  REGISTER_POLICY)
        if reply[1] & 0x7F:
            raise DeviceFault(f"servo {device_id} refused to {what}: "
                              f"{codec.Status(*reply).error_text()}", code=reply[1])
        return reply

    def read_table(self, device_id: int, address: int = 0, length: int = TABLE_SIZE) -> bytes:
        return self._request(device_id, codec.READ, codec.read_params(address, length),
                             f"read {length} bytes at {address}")[2]

    def read_register(self, device_id: int, item: Item) -> int:
        return item.decode(self.read_table(device_id, item.address, item.size))

    def write_register_item(self, device_id: int, item: Item, value: int) -> None:
        try:
            data = item.encode(value)
        except OverflowError:
            raise InvalidInput(f"{value} does not fit {item.name} ({item.size} byte(s))") \
                from None
        hint = " (EEPROM items need torque off)" if item.eeprom else ""
        self._request(device_id, codec.WRITE, codec.write_params(item.address, data),
                      f"write {item.name}{hint}")

    # -- lifecycle -------------------------------------------------------------------------------
    def configure(self) -> None:
        self.link.open()
        for device_id in self.joints:
            found = self.ping(device_id)
            if found is not None:
                self.present[device_id] = found
        self.roll_call([j.name for i, j in self.joints.items() if i not in self.present],
                       bool(self.present), "servo",
                       "check power, the baud rate and the IDs (deltoctl detect scans the "
                       "other baud rates)")
        self._check_models()
        self.connected = True

    def _check_models(self) -> None:
        """Each servo's reported model against the profile's: a mismatch is an error unless
        allowed (then a warning, and the servo's own table is used)."""
        wrong = [f"{self.joints[i].name} (ID {i}) is {label(m)}, the profile says "
                 f"{label(self.expected[i])}" for i, (m, _) in sorted(self.present.items())
                 if self.expected[i] is not None and m != self.expected[i]]
        if not wrong:
            return
        message = "model mismatch: " + "; ".join(wrong)
        if not self.allow_model_mismatch:
            raise DeviceError(message, hint="fix the profile's model_number or motor_type, "
                              "or pass --allow-model-mismatch to go on with the reported models")
        self.warnings.append(message + " (allowed; using each servo's own table)")

    def model(self, device_id: int) -> Model:
        """The model a servo reported (its table, units and modes)."""
        number = self.present[device_id][0]
        model = by_number(number)
        if model is None:
            raise DeviceError(f"{self.joints[device_id].name} (ID {device_id}) reports model "
                              f"number {number}, not an X-series model deltoctl knows")
        return model

    def identify(self) -> dict:
        servos = {}
        for i, (m, f) in sorted(self.present.items()):
            known = by_number(m)
            servos[self.joints[i].name] = {
                "id": i, "model_number": m, "model": known.name if known else None,
                "firmware": f, "profile_model": self.expected[i],
                "model_match": self.expected[i] is None or m == self.expected[i]}
        return {"bus": self.url, "servos": servos}

    def round_trip(self) -> None:
        """One ping of the first servo: what ``connect`` times."""
        self.ping(next(iter(self.present)))

    def _lost(self, exc: Exception) -> None:
        """The port went away (an adapter unplugged): the bus reads as lost, and is reopened
        once a second; a recording goes on meanwhile."""
        if self.connected:
            self.warnings.append(f"{self.hw.name}: {self.url} lost ({exc})")
        self.connected = False
        self.link.lost()

    def start_read(self) -> None:
        """The slow loop's exchange when due, then the fast loop's sync read sent; ``read``
        takes its replies (the other bus sends its own meanwhile)."""
        if self.port is None and self.link.reopen():
            self.connected = True
        self.sync.start(list(self.present))

    def read(self) -> dict[str, float]:
        if not self.sync.pending:
            self.start_read()
        self.sync.finish()
        return self.values

    def _take_pvl(self, replies: list[Reply]) -> None:
        """Present Load (or Current), Velocity and Position (126, 10 bytes)."""
        values = self.values
        for device_id, _, data in replies:
            joint = self.joints[device_id]
            load, velocity, position = PVL.unpack(data)
            name = joint.name
            values[name + "/position"] = (position - CENTER) * RAD_PER_RAW + joint.offset
            values[name + "/velocity"] = velocity * RAD_S_PER_RAW
            # 126 is the Present Current (A, in the model's unit) or, without a current
            # sensor, the Present Load
            unit = self._current_units.get(device_id)
            values[name + "/effort"] = load * (LOAD_SCALE if unit is None else unit)
            states = self.gpio_states.get(device_id)
            if states:
                self._servo_states(states, {
                    "Present Position": (position - CENTER) * RAD_PER_RAW,
                    "Present Velocity": velocity * RAD_S_PER_RAW,
                    "Present Current" if unit else "Present Load": load * (unit or 0.1)})

    def _servo_states(self, states: dict[str, str], readings: dict[str, float]) -> None:
        """A servo gpio's states, as the servo reports them: rad, rad/s, A, % of load, V, °C
        (a servo the profile reverses reports reversed values: deltoctl reverses it by its
        Drive Mode)."""
        for item, value in readings.items():
            name = states.get(item)
            if name is not None:
                self.values[name] = value

    @property
    def _current_units(self) -> dict[int, float | None]:
        """A per servo of Present Current's step (None: the servo reports load)."""
        units = self._units
        if units is None or len(units) != len(self.present):
            units = self._units = {i: _amps_per_step(m) for i, (m, _) in self.present.items()}
        return units

    def _sync_read(self, address: int, length: int, ids: list[int]) -> list[Reply]:
        """One sync read (or Fast Sync Read): ``(id, error, data)`` per valid reply; a missing
        or corrupted reply counts as an error, never raises."""
        return self.sync.read(address, length, ids)

    def bulk_read(self, reads: list[tuple[int, int, int]]) -> list[Reply]:
        """One Bulk Read of (ID, address, length) each: ``(id, error, data)`` per valid
        reply."""
        self.stats["packets"] += 1
        done = self.link.exchange(self.session, codec.BROADCAST_ID, codec.BULK_READ,
                                  codec.bulk_read_params(reads))
        self.stats["errors"] += not done.complete
        return done.replies

    def _take_voltage_temperature(self, replies: list[Reply]) -> None:
        """The slow loop: Present Input Voltage (144, 0.1 V) and Temperature (146, °C)."""
        for device_id, _, data in replies:
            name = self.joints[device_id].name
            voltage, temperature = struct.unpack("<Hb", data)
            self.values[f"{name}/voltage"] = voltage / 10.0
            self.values[f"{name}/temperature"] = float(temperature)
            states = self.gpio_states.get(device_id)
            if states:
                self._servo_states(states, {"Present Input Voltage": voltage / 10.0,
                                            "Present Temperature": float(temperature)})

    def _broadcast_ping(self, timeout: float) -> dict[int, int]:
        """ID → model number of every servo that answers a broadcast ping."""
        done = self.link.exchange(self.session, codec.BROADCAST_ID, codec.PING, b"", timeout)
        return {i: struct.unpack_from("<H", data)[0] for i, _, data in done.replies}

    def detect(self) -> dict:
        """Broadcast ping at the bus's rate; when a servo is missing, broadcast pings at
        every other XL430 rate too (all IDs at once), to find servos set to another rate."""
        assert self.port is not None
        found = self._broadcast_ping(0.3)
        expected = self.expected
        missing = sorted(set(expected) - set(found))
        elsewhere: dict[int, int] = {}
        unscanned = refused_rates(self.url, SCAN_BAUDS) if missing else {}
        if missing:
            own = self.port.baudrate
            try:
                for baud in SCAN_BAUDS:
                    if baud != own and baud not in unscanned:
                        self.port.baudrate = baud
                        # time for about 30 ping replies (14 bytes) at that rate
                        for i in self._broadcast_ping(max(0.1, 30 * 140 / baud)):
                            if i not in found:
                                elsewhere.setdefault(i, baud)
            finally:
                self.port.baudrate = own
        speaks_1 = other_protocol(self, [i for i in missing if i not in elsewhere], 2.0)
        return self._detect_report(found, missing, elsewhere, speaks_1, unscanned)

    def _detect_report(self, found: dict[int, int], missing: list[int],
                       elsewhere: dict[int, int], other: list[int],
                       unscanned: dict[int, str] | None = None) -> dict:
        """What detect found, as the verb reports it: the servos, those at another baud rate
        and those that answer in the bus's other protocol."""
        unscanned = unscanned or {}
        expected = self.expected
        protocol = "2.0" if self.protocol == 1.0 else "1.0"  # the other one
        unexpected = sorted(set(found) - set(expected))
        wrong = sorted(i for i in set(found) & set(expected)
                       if expected[i] is not None and found[i] != expected[i])
        name = {i: j.name for i, j in self.joints.items()}
        checks = [self._servo_check(i, name.get(i), model, found.get(i), elsewhere.get(i))
                  for i, model in sorted(expected.items())]
        checks += [{"what": f"ID {i}", "profile": "no servo", "device": label(found[i]),
                    "match": False} for i in unexpected]
        summary = (f"{self.hw.name}: {len(found)} servos answer ({len(missing)} missing, "
                   f"{len(unexpected)} unexpected)")
        if elsewhere:
            summary += "; at another baud rate: " + ", ".join(
                f"{name.get(i, i)} ({baud})" for i, baud in sorted(elsewhere.items()))
        if other:
            summary += f"; answering in Protocol {protocol}: " + ", ".join(
                f"{name.get(i, i)} (ID {i})" for i in other)
        checks += [{"what": f"{name.get(i, i)} (ID {i}) protocol",
                    "profile": "2.0" if protocol == "1.0" else "1.0", "device": protocol,
                    "match": False} for i in other]
        if unscanned:
            summary += "; not scanned: " + "; ".join(unscanned.values())
        return {"bus": self.url, "found": found, "missing": missing, "unexpected": unexpected,
                "wrong_model": wrong, "wrong_baud": {str(i): b for i, b in elsewhere.items()},
                "other_protocol": {str(i): protocol for i in other},
                "unscanned": {str(b): why for b, why in unscanned.items()},
                "checks": checks, "summary": summary}

    def _servo_check(self, servo_id: int, joint: str | None, model: int | None,
                     answer: int | None, baud: int | None) -> dict:
        """A servo the profile declares, as the bus answers for it: its model, no answer, or
        an answer at another baud rate only (``missing``: not at the bus's rate)."""
        device = "no answer" if answer is None else label(answer)
        if baud is not None:
            device = f"found at {baud} baud, not {self.port.baudrate}"
        return {"what": f"{joint or 'servo'} (ID {servo_id})", "part": joint,
                "profile": "a servo" if model is None else label(model), "device": device,
                "match": answer is not None and model in (None, answer),
                "missing": answer is None}

    def send_goals(self, goals: dict[str, float], seconds: float) -> None:
        """Torque on, then a profile to each goal through the PV writer (108, 12):
        acceleration 0, profile velocity, goal position. Drive Mode is set to a time-based
        profile (4), plus reverse (1) for an inverse joint — the MH5 inverts direction in the
        servo; a servo whose torque is already on keeps its mode (an EEPROM item), so the
        profile velocity follows the mode it reports: the move's duration in ms, or a speed in
        0.229 rpm. A servo turning the other way than the profile says is refused."""
        by_name = {j.name: i for i, j in self.joints.items() if i in self.present}
        ids = {by_name[name]: rad for name, rad in goals.items() if name in by_name}
        if not ids:
            return
        self.link.write(codec.sync_write(10, 1, {
            i: bytes([5 if self.joints[i].inverse else 4]) for i in ids}))
        modes = {i: self.read_register(i, DRIVE_MODE) for i in ids}
        reversed_wrong = [self.joints[i].name for i, mode in modes.items()
                          if bool(mode & 1) != self.joints[i].inverse]
        if reversed_wrong:
            raise Refused(f"{', '.join(reversed_wrong)}: the servo turns the other way than "
                          "the profile's inverse says, and its Drive Mode cannot change while "
                          "torque is on", hint="switch torque off for them, then move again")
        self._torque(list(ids), True)
        data = {}
        for i, rad in ids.items():
            joint = self.joints[i]
            if modes[i] & 4:  # time-based
                profile = max(1, round(seconds * 1000))
            else:
                now = self.values.get(f"{joint.name}/position", rad)
                profile = max(1, round(abs(rad - now) / seconds / RAD_S_PER_RAW))
            raw = round((rad - joint.offset) / RAD_PER_RAW + CENTER)
            data[i] = struct.pack("<IIi", 0, profile, raw)
        self.moving.update(ids)
        self.link.write(codec.sync_write(108, 12, data))
        self.link.flush()
        self.loops["pv_writer"].count(True)
        self.stats["packets"] += 2

    def set_torque(self, joints: list[str], on: bool) -> list[str]:
        """Torque Enable (64) for these joints of this bus; returns the ones it reached."""
        ids = {i: j.name for i, j in self.joints.items() if j.name in joints and i in self.present}
        if ids:
            self._torque(list(ids), on)
            self.link.flush()  # a sync write has no reply: be sure it left before returning
        return list(ids.values())

    def _torque(self, ids: list[int], on: bool) -> None:
        """The torque writer (64, 1)."""
        self.link.write(codec.sync_write(64, 1, {i: bytes([int(on)]) for i in ids}))
        self.loops["t_writer"].count(True)
        self.stats["packets"] += 1
        if on:
            self.torque_enabled.update(ids)
        else:
            self.torque_enabled.difference_update(ids)

    def reboot(self, joints: list[str]) -> list[str]:
        """REBOOT each servo (clears a shutdown); returns the ones that acknowledged."""
        done = []
        for i, joint in self.joints.items():
            if joint.name in joints and i in self.present:
                self.stats["packets"] += 1
                answer = self.link.exchange(self.session, i, codec.REBOOT, b"", timeout=0.5)
                if answer.replies and answer.replies[0][1] == 0:
                    done.append(joint.name)
                else:
                    self.stats["errors"] += 1
        return done

    def move(self, targets: dict[str, float], velocity: float | None = None,
             progress: Progress | None = None) -> MoveResult:
        """A time profile to each goal (the servos run their own position loop); returns once
        every servo says it stopped (Moving, 122, is 0) within tolerance of its goal, the
        timeout passes or the System halts the move."""
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
        # the setpoint each cycle: the goal, and the speed of its profile
        setpoints = {j: (t, abs(t - values.get(f"{j}/position", t)) / seconds, NAN)
                     for j, t in targets.items()} if hook is not None else {}
        if hook is not None:  # the state the goals were sent from
            hook(time.time_ns(), values, setpoints)
        start = time.monotonic()
        errors: dict[str, float] = {}
        arrived: list[str] = []
        while time.monotonic() - start < seconds + timeout and not self.halted.is_set():
            values = self.read()
            if hook is not None:
                hook(time.time_ns(), values, setpoints)
            errors = {j: abs(t - values.get(f"{j}/position", float("inf")))
                      for j, t in targets.items()}
            worst = max(errors.values(), default=0.0)
            if progress:
                progress(max(0.0, 1.0 - worst / (distance or 1.0)))
            still = self._stopped(list(targets))
            arrived = [j for j, e in errors.items() if e <= tolerance and j in still]
            if len(arrived) == len(targets):
                self.moving.clear()
                return MoveResult(True, time.monotonic() - start, errors, [])
            time.sleep(0.02)
        return MoveResult(False, time.monotonic() - start, errors,
                          [j for j in targets if j not in arrived])

    def _stopped(self, joints: list[str]) -> set[str]:
        """The joints whose servo says its profile is done (Moving, 122, reads 0); a servo
        that does not answer, or a bus whose port is lost, is not known to have stopped."""
        if self.port is None:
            return set()
        ids = {i: c.name for i, c in self.joints.items() if c.name in joints and i in self.present}
        replies = self._sync_read(MOVING.address, 1, list(ids)) if ids else []
        return {ids[i] for i, error, data in replies if i in ids and data and data[0] == 0}

    def follow(self, setpoints: dict[str, tuple[float, float, float]]) -> None:
        """A recorded goal (position) and its profile's speed (velocity) each, sent when they
        differ from the goal sent before: the servos run their own profile to it, as in the
        move that was recorded."""
        sent = self._followed
        goals = {j: sp for j, sp in setpoints.items()
                 if sp[0] == sp[0] and sent.get(j) != sp[:2]}
        if not goals:
            return
        seconds = 0.1
        for j, (goal, speed, _) in goals.items():
            if speed == speed and speed > 0:
                here = self.values.get(f"{j}/position", goal)
                seconds = max(seconds, abs(goal - here) / speed)
        self.send_goals({j: sp[0] for j, sp in goals.items()}, seconds)
        sent.update({j: sp[:2] for j, sp in goals.items()})

    # -- registers -------------------------------------------------------------------------------
    def servo(self, joint: str) -> int:
        """The ID of a joint's servo on this bus."""
        for device_id, comp in self.joints.items():
            if comp.name == joint:
                if device_id not in self.present:
                    raise NoAnswer(f"{joint} (ID {device_id}) does not answer on {self.url}")
                return device_id
        raise InvalidInput(f"{joint!r} is not a servo joint of {self.hw.name}")

    def read_registers(self, joint: str, items: list[str]) -> dict[str, Any]:
        """Control table items by name (all of them, in one read, when none are named), in
        the table of the servo's own model."""
        from deltoctl.families.dynamixel.control_table import item_named

        device_id = self.servo(joint)
        model = self.model(device_id)
        chosen = [item_named(i, model.table, model.name) for i in items]
        if chosen:
            values = {i.name: self.read_register(device_id, i) for i in chosen}
        else:
            table = self.read_table(device_id, 0, model.table_size)
            chosen = list(model.table)
            values = {i.name: i.of_table(table) for i in chosen}
        return {"joint": joint, "id": device_id, "model": model.name, "items": [
            {"address": i.address, "item": i.name, "value": values[i.name],
             "access": ("EEPROM " if i.eeprom else "RAM ") + i.access} for i in chosen]}

    def write_register(self, joint: str, item: str, value: int) -> int:
        """Write one item and return what it reads back. A goal position or velocity is a
        command like a move's: outside the joint's envelope it is refused, nothing written."""
        from deltoctl.families.dynamixel.control_table import item_named

        device_id = self.servo(joint)
        model = self.model(device_id)
        chosen = item_named(item, model.table, model.name)
        if chosen.access != "RW":
            raise InvalidInput(f"{chosen.name} is read-only")
        if not chosen.in_range(value):
            raise InvalidInput(f"{joint}: {chosen.name} {value} is outside the {model.name}'s "
                               f"documented range {chosen.low}..{chosen.high}")
        self._check_goal(device_id, chosen.name, value)
        self.write_register_item(device_id, chosen, value)
        return self.read_register(device_id, chosen)

    def _check_goal(self, device_id: int, item: str, raw: int) -> None:
        """A Goal Position (a step from the Present Position) or Goal Velocity in the units
        of the profile, checked against the joint's envelope."""
        from deltoctl.core.envelope import check_command

        joint = self.joints[device_id]
        if item == "Goal Position":
            here = self.read_register(device_id, BY_NAME["Present Position"])
            check_command(self.profile, joint, "position",
                          (raw - CENTER) * RAD_PER_RAW + joint.offset,
                          (here - CENTER) * RAD_PER_RAW + joint.offset)
        elif item == "Goal Velocity":
            check_command(self.profile, joint, "velocity", raw * RAD_S_PER_RAW, None)

    # -- configuration ---------------------------------------------------------------------------
    def config_read(self) -> dict[str, dict[str, dict[str, Any]]]:
        """The whole control table of every servo that answers (one read each), by item name
        with units; EEPROM items need torque off while the servo's is on."""
        parts = {}
        for device_id, joint in self.joints.items():
            if device_id not in self.present:
                continue  # configure warned already
            model = self.model(device_id)
            table = self.read_table(device_id, 0, model.table_size)
            values = {i.name: i.of_table(table) for i in model.table}
            parts[joint.name] = {i.name: self._config_entry(i, values, model)
                                 for i in model.table}
        return parts

    @staticmethod
    def _config_entry(item: Item, values: dict[str, int], model: Model) -> dict[str, Any]:
        from deltoctl.families.dynamixel.control_table import BUS_ITEMS, READINGS
        from deltoctl.families.dynamixel.models import MODE_NAMES

        value = values[item.name]
        low, high = item.span()
        entry: dict[str, Any] = {"value": value, "access": item.access,
                                 "area": "EEPROM" if item.eeprom else "RAM",
                                 "address": item.address, "min": low, "max": high}
        if item.low is not None and item.high is not None:  # the model's documented range
            entry["low"], entry["high"] = item.low, item.high
        unit = model.units().get(item.name)
        if item.name in ("Profile Acceleration", "Profile Velocity") and values["Drive Mode"] & 4:
            unit = "ms"  # a time-based profile
        if unit:
            entry["unit"] = unit
        bauds = {code: f"{baud} bps" for code, baud in BAUD_RATES.items()}
        modes = {m: MODE_NAMES[m] for m in sorted(model.modes)}
        meaning = {"Baud Rate": bauds, "Operating Mode": modes}.get(item.name, {})
        if value in meaning:
            entry["meaning"] = meaning[value]
        if item.name in READINGS:
            entry["state"] = True
        elif item.name in BUS_ITEMS:
            entry["fixed"] = ("it changes how the servo answers on its bus: use deltoctl "
                              "register set")
        elif item.eeprom and item.access == "RW" and values["Torque Enable"]:
            entry["needs"] = "torque-off"
        return entry

    def config_write(self, changes: dict[str, dict[str, Any]],
                     allow: frozenset[str] = frozenset()) -> dict[str, dict[str, Any]]:
        """Per servo, EEPROM items then RAM items, each in address order, then one read of
        the table. EEPROM takes writes only with torque off (as Dynamixel Wizard): a servo
        whose torque is on is refused, before anything is written, unless ``allow`` holds
        "torque-off"; its torque then goes off for the writes and comes back on holding where
        the servo is, as it was found."""
        plan = {self.servo(part): sorted(((self._restorable(part, name, value), value)
                                          for name, value in items.items()),
                                         key=lambda w: (not w[0].eeprom, w[0].address))
                for part, items in changes.items()}
        torque = BY_NAME["Torque Enable"]
        locked = {i for i, writes in plan.items() if any(item.eeprom for item, _ in writes)
                  and self.read_register(i, torque)}
        if locked and "torque-off" not in allow:
            raise Refused(f"{', '.join(self.joints[i].name for i in sorted(locked))}: EEPROM "
                          "items are written only with torque off, and the torque is on",
                          hint="switch it off first (deltoctl torque off), or pass --allow "
                               "torque-off to have it switched off for the writes and on "
                               "again (support the robot)")
        read_back = {}
        for device_id, writes in plan.items():
            self._write_servo(device_id, writes, device_id in locked)
            table = self.read_table(device_id, 0, self.model(device_id).table_size)
            read_back[self.joints[device_id].name] = {
                item.name: item.of_table(table) for item, _ in writes}
        return read_back

    def _restorable(self, part: str, name: str, value: Any) -> Item:
        """The item, when a restore may write it to this servo (not a reading, a command or
        a bus setting; a value within the range its model's e-manual page documents)."""
        from deltoctl.families.dynamixel.control_table import BUS_ITEMS, READINGS

        model = self.model(self.servo(part))
        item = model.by_name.get(name)
        if item is None or item.access != "RW" or name in READINGS or name in BUS_ITEMS:
            raise InvalidInput(f"{part}: {name!r} is not a control table item a restore writes")
        try:  # checked before any write: a restore is refused whole, never half done
            if isinstance(value, bool):
                raise TypeError
            item.encode(value)
        except (AttributeError, OverflowError, TypeError):
            raise InvalidInput(f"{part}: {name} takes an integer of {item.size} byte(s), "
                               f"{'signed' if item.signed else 'unsigned'}, not {value!r}") \
                from None
        if (item.low is not None and value < item.low) or (item.high is not None
                                                           and value > item.high):
            raise InvalidInput(f"{part}: {name} {value} is outside the {model.name}'s "
                               f"documented range {item.low}..{item.high}")
        return item

    def _write_servo(self, device_id: int, writes: list[tuple[Item, int]],
                     torque_off: bool) -> None:
        torque = BY_NAME["Torque Enable"]
        if torque_off:
            self.write_register_item(device_id, torque, 0)
            self.torque_enabled.discard(device_id)
        try:
            for item, value in writes:
                self.write_register_item(device_id, item, value)
        finally:
            if torque_off:  # on again as found, holding where the servo is now: no jump
                here = self.read_register(device_id, BY_NAME["Present Position"])
                self.write_register_item(device_id, BY_NAME["Goal Position"], here)
                self.write_register_item(device_id, torque, 1)

    def stop(self) -> None:
        """A move still under way stops where it is (goal = present position); the torque
        stays as it was found: a humanoid must not drop when a verb ends."""
        if not self.moving or self.port is None:
            return
        ids = sorted(self.moving)
        self.moving.clear()
        for _ in range(POLICY.tries):  # the stop must get through a noisy bus
            here = {i: data for i, _, data in self._sync_read(132, 4, ids)}
            if here:
                self.link.write(codec.sync_write(116, 4, here))
                self.link.flush()
            ids = [i for i in ids if i not in here]
            if not ids:
                return
        self.warnings.append(f"{self.hw.name}: no present position from "
                             f"{', '.join(self.joints[i].name for i in ids)} to stop them at")

    def make_safe(self) -> None:
        """Every servo of the block stops where it is (goal = present position), whatever
        this session moved; the torque stays on (an arm must not fall)."""
        self.moving.update(self.joints)
        self.stop()

    # -- joint calibration (LeRobot's: present = actual + Homing Offset) ------------------------
    calibration_registers: ClassVar[dict[str, str]] = {
        "drive_mode": "Drive Mode", "homing_offset": "Homing Offset",
        "range_min": "Min Position Limit", "range_max": "Max Position Limit"}
    lerobot_types = ("koch_follower", "koch_leader")

    def joint_calibration(self) -> dict[str, dict[str, int]]:
        """Drive Mode (10), Homing Offset (20) and the position limits (48, 52) of each servo,
        in one read of 10..55."""
        found = {}
        for device_id, joint in self.joints.items():
            if device_id not in self.present:
                continue
            table = bytes(10) + self.read_table(device_id, 10, 46)
            found[joint.name] = {"id": device_id, "resolution": 4096, **{
                key: BY_NAME[item].of_table(table)
                for key, item in self.calibration_registers.items()}}
        return found

    def _present_positions(self) -> dict[int, int]:
        ids = [i for i in self.joints if i in self.present]
        return {i: struct.unpack("<i", data)[0] for i, _, data in self._sync_read(132, 4, ids)
                if len(data) == 4}

    def middle_offsets(self) -> dict[str, int]:
        """LeRobot's half-turn homing: the offset that makes each present pose read 2047."""
        item = BY_NAME["Homing Offset"]
        offsets = {}
        for device_id, present in self._present_positions().items():
            held = self.read_register(device_id, item)
            offset = CENTER - (present - held)
            if not item.in_range(offset):
                raise DeviceError(f"{self.joints[device_id].name}: an offset of {offset} is "
                                  f"beyond Homing Offset's range ({item.low}..{item.high})",
                                  hint="reboot the servo (its multi-turn count resets), then "
                                       "calibrate again")
            offsets[self.joints[device_id].name] = offset
        return offsets

    def positions_under(self, offsets: dict[str, int],
                        held: dict[str, int]) -> dict[str, int]:
        return {self.joints[i].name: here - held.get(self.joints[i].name, 0)
                + offsets.get(self.joints[i].name, 0)
                for i, here in self._present_positions().items()}

    def write_joint_calibration(self, values: dict[str, dict[str, int]]) -> None:
        """Torque off, then Homing Offset and the position limits (EEPROM: torque off)."""
        torque = BY_NAME["Torque Enable"]
        for joint, entry in values.items():
            device_id = self.servo(joint)
            self.write_register_item(device_id, torque, 0)
            self.torque_enabled.discard(device_id)
            for key in ("homing_offset", "range_min", "range_max"):
                self.write_register_item(device_id, BY_NAME[self.calibration_registers[key]],
                                         entry[key])

    def cleanup(self) -> None:
        self.link.close()
        self.connected = False
