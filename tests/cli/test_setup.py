"""deltoctl setup: a factory-new koch-arm and so101-follower set up one servo at a time on the
simulators — in-process (--sim: the simulator connects each part), and on a ``sim serve
--factory-new`` whose parts are connected by control lines on its standard input — then
identify clean, and the vendors' SDKs confirm each ID and rate. In place: a swap through a
temporary ID. Refusals: colliding parts (nothing written), another model, a joint the profile
lacks, a factory reset without --allow, no confirmation."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
from deltoctl.families.dynamixel.emulator1 import MixedBus, Protocol1Bus, Servo1
from deltoctl.families.dynamixel.models import by_number
from deltoctl.schemas_lookup import schema_file

WAIT = ("--wait", "0.05")  # s a probe waits: generous, a loaded machine answers late
ARM = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
KOCH_MODELS = (1060, 1060, 1200, 1200, 1200, 1200)  # XL430-W250 ×2, XL330-M288 ×4


def _doc(result):
    document = json.loads(result.stdout)
    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.validate(document, json.loads(schema_file("setup").read_text()))
    return document["result"]


def _confirmed_by_the_sdk(profile: str, path: str) -> None:
    """dynamixel-sdk (koch-arm) or scservo_sdk (so101-follower) pings IDs 1–6 at 1 Mbps,
    each reply awaited 0.5 s (the SDKs' 34 ms is short on a loaded machine)."""
    if profile == "koch-arm":
        sdk = pytest.importorskip("dynamixel_sdk")
        port, ph, models = sdk.PortHandler(path), sdk.PacketHandler(2.0), KOCH_MODELS
    else:
        sdk = pytest.importorskip("scservo_sdk")
        port, ph, models = sdk.PortHandler(path), sdk.PacketHandler(0), (777,) * 6
    assert port.openPort() and port.setBaudRate(1_000_000)
    port.setPacketTimeout = lambda _length: port.setPacketTimeoutMillis(500)
    try:
        for device_id, model in enumerate(models, 1):
            assert ph.ping(port, device_id) == (model, sdk.COMM_SUCCESS, 0), device_id
    finally:
        port.closePort()


@pytest.mark.parametrize("profile", ["koch-arm", "so101-follower"])
def test_a_factory_new_arm_in_process_then_identify_clean(profile):
    from deltoctl.app.robot import open_robot
    from deltoctl.app.setup import open_setup

    with open_setup(profile, sim={"factory_new": True}, wait=0.05) as run:
        walked = []
        for w in run.walk_order():
            assert run.connect_alone(w.joint) == f"on the wire: {w.joint}"
            done = run.apply_one(w.joint, run.plan_one(w.joint, walked=walked))
            assert done.joints[0]["verified"]
            walked.append(w.joint)
        assert run.controls.run("connect all").endswith(", ".join(ARM))
        [target] = run.targets()
        url = target.partition("=")[2]
        with open_robot(profile, [target]) as robot:
            report = robot.identify()
            assert robot.warnings() == []
        assert report  # every servo answered at its ID, the right model
        _confirmed_by_the_sdk(profile, url.split("?")[0].removeprefix("serial://"))


@pytest.mark.parametrize("profile", ["koch-arm", "so101-follower"])
def test_the_cli_sets_up_a_factory_new_arm_on_its_own_simulator(cli, profile):
    result = cli("-p", profile, "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "--json", "setup", "--yes", *WAIT)
    assert result.exit_code == 0, result.output
    doc = _doc(result)
    order = list(ARM) if profile == "koch-arm" else [*ARM[1:], ARM[0]]  # 1 @ 1 Mbps: last
    assert [r["joint"] for r in doc["joints"]] == order
    assert all(r["verified"] for r in doc["joints"])
    assert [r["to"]["id"] for r in doc["joints"]] == [ARM.index(j) + 1 for j in order]
    assert "the simulator connected gripper alone" in result.stderr
    assert ("shoulder_pan last" in result.stderr) == (profile == "so101-follower")


def _served(profile):
    """`deltoctl sim serve PROFILE --factory-new` with its standard input ours."""
    proc = subprocess.Popen([sys.executable, "-m", "deltoctl", "sim", "serve", profile,
                             "--json", "--factory-new", "--private"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    [(bus, url)] = json.loads(proc.stdout.readline())["buses"].items()
    return proc, bus, url


def _control(proc, line: str) -> str:
    proc.stdin.write(line + "\n")
    proc.stdin.flush()
    return json.loads(proc.stdout.readline())["reply"]


@pytest.mark.parametrize("profile", ["koch-arm", "so101-follower"])
def test_setup_joint_by_joint_on_a_sim_serve_then_identify_clean(cli, profile):
    proc, bus, url = _served(profile)
    target = f"{bus}={url}"
    try:
        for joint in ARM:
            assert _control(proc, f"connect {joint}") == f"on the wire: {joint}"
            result = cli("-p", profile, "-t", target, "--json", "setup", joint, "--yes", *WAIT)
            if profile == "so101-follower" and joint != "shoulder_pan":
                # a new servo answers at shoulder_pan's ID and rate (the factory's): which it
                # is, is not known; alone, it is given its joint's by setup --in-place --map
                assert result.exit_code == 5, result.output
                assert f"--map 1={joint}" in result.stderr
                result = cli("-p", profile, "-t", target, "--json", "setup", "--in-place",
                             "--map", f"1={joint}", "--yes", *WAIT)
                assert result.exit_code == 3, result.output  # the others: not connected
            else:
                assert result.exit_code == 0, result.output
            row = next(r for r in _doc(result)["joints"] if r["joint"] == joint)
            assert row["verified"] and row["from"]["id"] == 1
        assert _control(proc, "connect all").startswith("on the wire: shoulder_pan")
        result = cli("-p", profile, "-t", target, "identify")
        assert result.exit_code == 0, result.output
        _confirmed_by_the_sdk(profile, url.split("?")[0].removeprefix("serial://"))
    finally:
        proc.terminate()
        proc.wait(timeout=5)


def _count_writes(monkeypatch, cls):
    writes = []
    original = cls.write

    def counted(self, address, data):
        writes.append((self.id, address, bytes(data)))
        return original(self, address, data)

    monkeypatch.setattr(cls, "write", counted)
    return writes


def test_colliding_parts_are_named_and_nothing_is_written(cli, monkeypatch):
    writes = _count_writes(monkeypatch, Servo)
    twins = [Servo(1, model=by_number(1200)) for _ in range(2)]
    twins[1].position += 300  # another pose: alike, they would ping as one
    bus = MixedBus(*(DynamixelBus([twin], baud=57_600) for twin in twins))
    with DynamixelPtyServer(bus) as server:
        result = cli("-p", "koch-arm", "-t", f"dxl=serial://{server.port}?baud=1000000",
                     "setup", "elbow_flex", "--yes", *WAIT)
    assert result.exit_code == 5, result.output
    assert "several servos answer at ID 1" in result.stderr
    assert "collide" in result.stderr and "alone" in result.stderr
    assert writes == []


def test_a_servo_of_another_model_is_refused(cli, monkeypatch):
    writes = _count_writes(monkeypatch, Servo1)
    with DynamixelPtyServer(Protocol1Bus([Servo1(1)], baud=57_600)) as server:
        result = cli("-p", "koch-arm", "-t", f"dxl=serial://{server.port}?baud=1000000",
                     "setup", "shoulder_pan", "--yes", *WAIT)
    assert result.exit_code == 5, result.output
    assert "AX-12A" in result.stderr and "XL430-W250" in result.stderr
    assert writes == []


def test_in_place_swap_through_a_temporary_id(cli):
    models = [by_number(n) for n in KOCH_MODELS]
    servos = [Servo(2, model=models[0]), Servo(1, model=models[1]),
              *(Servo(i, model=m) for i, m in zip(range(3, 7), models[2:]))]
    servos[0].set("Firmware Version", 45)  # shoulder_pan's, to find it again
    bus = DynamixelBus(servos, baud=1_000_000)
    with DynamixelPtyServer(bus) as server:
        target = f"dxl=serial://{server.port}?baud=1000000"
        dry = cli("-p", "koch-arm", "-t", target, "--json", "setup", "--in-place",
                  "--map", "2=shoulder_pan", "--map", "1=shoulder_lift", "--dry-run", *WAIT)
        assert dry.exit_code == 0, dry.output
        steps = [(s["action"], s["at_id"], s["value"]) for s in _doc(dry)["steps"]]
        assert set(bus.servos) == {1, 2, 3, 4, 5, 6}  # a dry run writes nothing
        result = cli("-p", "koch-arm", "-t", target, "--json", "setup", "--in-place",
                     "--map", "2=shoulder_pan", "--map", "1=shoulder_lift", "--yes", *WAIT)
        assert result.exit_code == 0, result.output
        assert all(r["verified"] for r in _doc(result)["joints"])
    ids = [s for s in steps if s[0] == "id"]
    assert ids == [("id", 2, 252), ("id", 1, 2), ("id", 252, 1)]  # the temporary ID 252
    assert bus.servos[1].get("Firmware Version") == 45
    assert set(bus.servos) == {1, 2, 3, 4, 5, 6}


def test_in_place_ambiguity_asks_for_a_map(cli):
    models = [by_number(n) for n in KOCH_MODELS]
    servos = [Servo(i, model=m) for i, m in zip((11, 12, 3, 4, 5, 6), models)]
    with DynamixelPtyServer(DynamixelBus(servos, baud=1_000_000)) as server:
        result = cli("-p", "koch-arm", "-t", f"dxl=serial://{server.port}?baud=1000000",
                     "setup", "--in-place", "--yes", *WAIT)
    assert result.exit_code == 2, result.output
    assert "--map" in result.stderr and "11, 12" in result.stderr


def test_a_factory_reset_needs_allow(cli):
    result = cli("-p", "koch-arm", "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "setup", "elbow_flex", "--factory-reset", "all", "--yes")
    assert result.exit_code == 5, result.output
    assert "--allow factory-reset" in result.stderr
    result = cli("-p", "koch-arm", "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "--json", "setup", "elbow_flex", "--factory-reset", "keep-id-baud",
                 "--allow", "factory-reset", "--yes", *WAIT)
    assert result.exit_code == 0, result.output
    assert [s["action"] for s in _doc(result)["steps"]][:1] == ["factory reset"]


def test_feetech_has_no_factory_reset(cli):
    result = cli("-p", "so101-follower", "--sim", "--sim-fresh", "--sim-option",
                 "factory_new", "setup", "gripper", "--factory-reset", "all", "--allow",
                 "factory-reset", "--yes")
    assert result.exit_code == 2, result.output
    assert "no factory reset" in result.stderr


@pytest.mark.parametrize(("args", "code", "said"), [
    (("setup", "elbow", "--yes"), 2, "no servo joint 'elbow'"),
    (("setup", "elbow_flex"), 5, "--yes"),
    (("setup", "--in-place", "--map", "x=elbow_flex", "--yes"), 2, "ID=JOINT"),
    (("setup", "--in-place", "--map", "\u00b2=elbow_flex", "--yes"), 2, "ID=JOINT"),
    (("setup", "--in-place", "--map", "300=elbow_flex", "--yes"), 2, "ID 300 is not 0-252"),
    (("-t", "dxll=serial:///dev/null", "setup", "elbow_flex", "--yes"), 2,
     "unknown bus 'dxll'"),
])
def test_refusals_and_bad_input(cli, args, code, said):
    result = cli("-p", "koch-arm", "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 *args)
    assert result.exit_code == code, result.output
    assert said in result.stderr and "Traceback" not in result.output


def test_a_script_names_the_joint_without_a_simulator_to_connect_it(cli):
    with DynamixelPtyServer(DynamixelBus([], baud=57_600)) as server:
        result = cli("-p", "koch-arm", "-t", f"dxl=serial://{server.port}?baud=1000000",
                     "setup", "--yes", *WAIT)
    assert result.exit_code == 2
    assert "setup JOINT" in result.stderr


def test_in_place_on_a_feetech_bus_reversed_and_at_another_rate(cli):
    from deltoctl.families.feetech.emulator import FeetechBus, FeetechPtyServer
    from deltoctl.families.feetech.emulator import Servo as FeetechServo

    servos = [FeetechServo(i) for i in range(6, 0, -1)]  # shoulder_pan's at ID 6 …
    for k, servo in enumerate(servos):
        servo.memory[0] = 10 + k  # a mark of each (its firmware's major), to follow it
    bus = FeetechBus(servos, baud=500_000)
    maps = [a for k, joint in enumerate(ARM) for a in ("--map", f"{6 - k}={joint}")]
    with FeetechPtyServer(bus) as server:
        result = cli("-p", "so101-follower", "-t",
                     f"so_bus=serial://{server.port}?baud=1000000", "--json", "setup",
                     "--in-place", *maps, "--yes", *WAIT)
        assert result.exit_code == 0, result.output
        doc = _doc(result)
    assert all(r["verified"] for r in doc["joints"])
    assert [s["value"] for s in doc["steps"] if s["action"] == "id"].count(252) == 3
    for servo in servos:
        servo.power_cycle()  # the EEPROM was locked again: it keeps them
    assert [(s.id, s.baud, s.memory[0]) for s in servos] == \
        [(k + 1, 1_000_000, 10 + k) for k in range(6)]


def test_in_place_never_writes_a_servo_the_profile_lacks(cli, monkeypatch):
    writes = _count_writes(monkeypatch, Servo)
    models = [by_number(n) for n in (*KOCH_MODELS, 1200)]
    servos = [Servo(i, model=m) for i, m in zip((1, 2, 3, 4, 5, 16, 9), models)]
    with DynamixelPtyServer(DynamixelBus(servos, baud=1_000_000)) as server:
        result = cli("-p", "koch-arm", "-t", f"dxl=serial://{server.port}?baud=1000000",
                     "setup", "--in-place", "--map", "16=gripper", "--yes", *WAIT)
    assert result.exit_code == 5, result.output
    assert "ID 9 is no joint of the profile" in result.stderr
    assert writes == []


def test_a_protocol_1_arm_is_set_up_and_reset_its_factory_address_last(cli):
    result = cli("-p", "phantomx-arm", "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "--json", "setup", "--factory-reset", "all", "--allow", "factory-reset",
                 "--yes", *WAIT)
    assert result.exit_code == 0, result.output
    rows = _doc(result)["joints"]
    assert [r["joint"] for r in rows] == ["shoulder", "elbow", "wrist", "gripper", "waist"]
    assert {(r["from"]["id"], r["from"]["baud"], r["from"]["protocol"], r["from"]["model"])
            for r in rows} == {(1, 1_000_000, "Dynamixel 1.0", "AX-12A")}  # an AX's factory
    assert [(r["to"]["id"], r["to"]["baud"], r["verified"]) for r in rows] == \
        [(i, 1_000_000, True) for i in (2, 3, 4, 5, 1)]
    assert "waist last" in result.stderr


def test_a_robot_on_its_own_simulators_runs_their_control_lines():
    from deltoctl.app.robot import open_robot
    from deltoctl.errors import InvalidInput

    with open_robot("mh5", sim=True, hardware=("i2c",)) as robot:
        assert robot.control("face -z")
        with pytest.raises(InvalidInput, match="unknown control"):
            robot.control("spin")
    with open_robot("koch-arm", sim=True) as robot, \
            pytest.raises(InvalidInput, match="unknown control 'connect'"):
        robot.control("connect gripper")  # parts are plugged one by one only factory-new


def test_in_place_with_a_servo_missing_warns(cli):
    servos = [Servo(i, model=by_number(n)) for i, n in zip(range(1, 6), KOCH_MODELS)]
    with DynamixelPtyServer(DynamixelBus(servos, baud=1_000_000)) as server:
        result = cli("-p", "koch-arm", "-t", f"dxl=serial://{server.port}?baud=1000000",
                     "--json", "setup", "--in-place", "--yes", *WAIT)
    assert result.exit_code == 3, result.output
    rows = _doc(result)["joints"]
    assert [r["status"] for r in rows] == ["already set"] * 5 + ["missing"]
    assert "not found, left alone: gripper" in result.stderr


def test_a_joint_set_up_already_and_left_connected_is_not_taken_for_the_next():
    from deltoctl.app.setup import open_setup
    from deltoctl.errors import Refused

    with open_setup("koch-arm", sim={"factory_new": True}, wait=0.05) as run:
        run.connect_alone("shoulder_pan")
        run.apply_one("shoulder_pan", run.plan_one("shoulder_pan"))  # ID 1, 1 Mbps now
        with pytest.raises(Refused, match="shoulder_pan's, set up already"):
            run.plan_one("shoulder_lift")  # shoulder_lift's servo not plugged in
        run.controls.run("connect shoulder_lift")
        assert run.plan_one("shoulder_lift").steps  # its own, at the factory's ID and rate


def test_in_place_refuses_one_id_at_two_rates(cli, monkeypatch):
    writes = _count_writes(monkeypatch, Servo)
    models = [by_number(n) for n in KOCH_MODELS]
    at_1m = DynamixelBus([Servo(i, model=m) for i, m in zip((2, 3, 4, 5, 6), models[1:])],
                         baud=1_000_000)
    slow = DynamixelBus([Servo(2, model=models[0])], baud=57_600)  # shoulder_pan's, at ID 2
    with DynamixelPtyServer(MixedBus(at_1m, slow)) as server:
        result = cli("-p", "koch-arm", "-t", f"dxl=serial://{server.port}?baud=1000000",
                     "setup", "--in-place", "--map", "2=shoulder_lift", "--yes", *WAIT)
    assert result.exit_code == 5, result.output
    assert "ID 2 answers at 57600 and 1000000 baud" in result.stderr
    assert writes == []


def test_one_at_a_time_refuses_a_target_id_held_already(cli, monkeypatch):
    writes = _count_writes(monkeypatch, Servo1)
    new = Protocol1Bus([Servo1(1)], baud=57_600)  # the factory's ID, unlike elbow's
    held = Protocol1Bus([Servo1(3)], baud=1_000_000)  # a servo at elbow's ID and rate already
    with DynamixelPtyServer(MixedBus(new, held)) as server:
        result = cli("-p", "phantomx-arm", "-t",
                     f"dxl=serial://{server.port}?baud=1000000", "setup", "elbow",
                     "--yes", *WAIT)
    assert result.exit_code == 5, result.output
    assert "a servo answers at ID 3, 1000000 baud" in result.stderr
    assert writes == []


def test_verification_tells_two_alike_servos_at_one_id():
    from deltoctl.app.setup import open_setup
    from deltoctl.errors import DeviceError

    model = by_number(1200)
    new = DynamixelBus([Servo(1, model=model)], baud=57_600)
    twin = DynamixelBus([], baud=1_000_000)
    with DynamixelPtyServer(MixedBus(new, twin)) as server, \
            open_setup("koch-arm", [f"dxl=serial://{server.port}?baud=1000000"],
                       wait=0.05) as run:
        plan = run.plan_one("elbow_flex")
        alike = Servo(3, model=model)  # elbow_flex's ID and rate, plugged in meanwhile
        alike.position += 300  # another pose: its PING is byte for byte the new one's
        twin.servos[3] = alike
        with pytest.raises(DeviceError, match="several servos answer at ID 3"):
            run.apply_one("elbow_flex", plan)


def test_a_walk_checks_the_factory_reset_of_every_joint_before_asking(cli):
    result = cli("-p", "so101-follower", "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "setup", "--factory-reset", "all", "--allow", "factory-reset")
    assert result.exit_code == 2, result.output
    assert "no factory reset" in result.stderr
    result = cli("-p", "koch-arm", "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "setup", "--factory-reset", "keep-id", "--allow", "factory-reset")
    assert result.exit_code == 5, result.output
    assert "factory reset (keep-id) of each" in result.stderr


def test_a_servo_at_the_factory_address_of_a_joint_set_up_is_not_taken_for_the_next():
    from deltoctl.app.setup import open_setup
    from deltoctl.errors import Refused

    with open_setup("so101-follower", sim={"factory_new": True}, wait=0.05) as run:
        run.connect_alone("shoulder_pan")
        done = run.apply_one("shoulder_pan", run.plan_one("shoulder_pan"))
        assert done.joints[0]["status"] == "already set"  # 1 @ 1 Mbps: the factory's
        with pytest.raises(Refused, match="a new servo or shoulder_pan's is not known"):
            run.plan_one("shoulder_lift")  # setup JOINT: shoulder_pan's, or a new one?
        with pytest.raises(Refused, match="is not known"):  # a walk that set it up already
            run.plan_one("shoulder_lift", walked=["shoulder_pan"])
        run.controls.run("connect shoulder_lift")
        assert run.plan_one("shoulder_lift", walked=[]).steps  # a walk sets shoulder_pan last


def test_the_input_closed_at_a_prompt_stops_the_walk_with_nothing_written(cli, monkeypatch):
    from deltoctl.cli import confirm, setup_cmd

    monkeypatch.setattr(confirm, "on_terminal", lambda: True)
    monkeypatch.setattr(setup_cmd, "on_terminal", lambda: True)
    servos = [Servo(1, model=by_number(n)) for n in KOCH_MODELS]
    bus = MixedBus(*[DynamixelBus([s], baud=57_600) for s in servos])
    with DynamixelPtyServer(bus) as server:
        result = cli("-p", "koch-arm", "-t", f"dxl=serial://{server.port}?baud=1000000",
                     "setup", "--wait", "0.05", input="y\n")
    assert result.exit_code == 130, result.output
    assert "input closed: setup stopped before" in result.stderr
    assert all((s.id, s.memory[8]) == (1, 1) for s in servos)  # ID 1, 57,600 still
