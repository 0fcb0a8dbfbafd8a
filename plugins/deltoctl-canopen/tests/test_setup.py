"""``deltoctl setup`` for CANopen drives: a factory-new two-axis profile given its node IDs
over LSS — in-process (--sim: the simulator plugs each drive in), and on a ``sim serve
--factory-new`` whose drives are plugged in by control lines, ``setup JOINT`` per joint —
then identify clean, and canopen's own SDO client reads each node's identity. Refusals: two
drives nobody names, connected at once (nothing written); a dry run writes nothing."""

import contextlib
import json
import os
import subprocess

import canopen
import pytest
from conftest import DELTOCTL, PROFILE
from deltoctl.profile.catalog import load_profile
from deltoctl.schemas_lookup import schema_file
from deltoctl.sim.controls import Controls
from deltoctl.sim.serve import ServeOptions, serve_profile

from deltoctl_canopen import lss
from deltoctl_canopen.transport import open_bus, parse_can_url


def _doc(result):
    document = json.loads(result.stdout)
    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.validate(document, json.loads(schema_file("setup").read_text()))
    return document["result"]


@contextlib.contextmanager
def _network(url):
    """canopen's own network on the bus at ``url``."""
    network = canopen.Network(open_bus(parse_can_url(url)))
    network.connect()
    try:
        yield network
    finally:
        network.disconnect()


def _serials_at(url, node_ids=(2, 3)):
    """0x1018:4 of each node ID, read with canopen's SDO client (None: no answer)."""
    out = {}
    with _network(url) as network:
        for node_id in node_ids:
            node = network.add_node(node_id)
            try:
                out[node_id] = int.from_bytes(node.sdo.upload(0x1018, 4), "little")
            except canopen.SdoCommunicationError:
                out[node_id] = None
            finally:
                del network[node_id]
    return out


@pytest.fixture
def box():
    """The two-axis profile's drives served factory-new in this process (all plugged in):
    their bus URL, control lines and serials."""
    with contextlib.ExitStack() as stack:
        controls = Controls()
        result = serve_profile(stack, load_profile(str(PROFILE)),
                               ServeOptions(factory_new=True), controls=controls)
        yield result["endpoint"], controls, result["blocks"]["axes"]["lss_serials"]


def test_a_factory_new_two_axis_in_process_then_identify_clean():
    from deltoctl.app.robot import open_robot
    from deltoctl.app.setup import open_setup

    with open_setup(str(PROFILE), sim={"factory_new": True}) as run:
        assert run.ask_line("axis_2").startswith("connect axis_2's drive (those set up may")
        for w in run.joints():
            assert run.connect_alone(w.joint) == f"canopen: {w.joint} connected"
            done = run.apply_one(w.joint, run.plan_one(w.joint))
            assert done.joints[0]["status"] == "set" and done.joints[0]["verified"]
        [target] = run.targets()
        with open_robot(str(PROFILE), [target]) as robot:
            assert robot.identify()
            assert robot.warnings() == []
        serials = _serials_at(target.partition("=")[2])
        # again: both answer at their node IDs, nothing to write
        assert [run.plan_one(w.joint).steps for w in run.joints()] == [[], []]
    assert None not in serials.values() and len(set(serials.values())) == 2


def test_the_cli_sets_up_the_two_axis_on_its_own_simulator(cli):
    result = cli("-p", PROFILE, "--sim", "--sim-fresh", "--sim-option", "factory_new",
                 "--json", "setup", "--yes")
    assert result.exit_code == 0, result.output + result.stderr
    doc = _doc(result)
    assert [(r["joint"], r["from"]["id"], r["to"]["id"], r["status"], r["verified"])
            for r in doc["joints"]] == [("axis_1", None, 2, "set", True),
                                        ("axis_2", None, 3, "set", True)]
    assert [(s["joint"], s["action"], s["value"]) for s in doc["steps"]] == [
        ("axis_1", "id", 2), ("axis_1", "store", 1_000_000),
        ("axis_2", "id", 3), ("axis_2", "store", 1_000_000)]
    assert doc["bus_seconds"] > 0
    assert "the simulator connected axis_2 alone" in result.stderr


def test_setup_joint_by_joint_on_a_sim_serve_then_identify_clean(cli):
    proc = subprocess.Popen([*DELTOCTL, "sim", "serve", str(PROFILE), "--factory-new", "--json"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        served = json.loads(proc.stdout.readline())
        url, serials = served["endpoint"], served["blocks"]["axes"]["lss_serials"]

        def control(line):
            proc.stdin.write(line + "\n")
            proc.stdin.flush()
            return json.loads(proc.stdout.readline())["reply"]

        assert control("disconnect all") == "canopen: axis_1, axis_2 disconnected"
        for joint in ("axis_1", "axis_2"):  # the one set up before stays connected
            assert control(f"connect {joint}") == f"canopen: {joint} connected"
            result = cli("-p", PROFILE, "-t", url, "--json", "setup", joint, "--yes")
            assert result.exit_code == 0, result.output + result.stderr
            [row] = _doc(result)["joints"]
            assert row["verified"] and row["from"]["serial"] == serials[joint]
        result = cli("-p", PROFILE, "-t", url, "identify")
        assert result.exit_code == 0, result.output + result.stderr
        assert _serials_at(url) == {2: serials["axis_1"], 3: serials["axis_2"]}
        result = cli("-p", PROFILE, "-t", url, "--json", "setup", "axis_1", "--yes")
        assert _doc(result)["joints"][0]["status"] == "already set"
    finally:
        proc.terminate()
        proc.wait(5)


def test_two_unnamed_drives_connected_at_once_are_refused(cli, box):
    url, _, _ = box
    result = cli("-p", PROFILE, "-t", url, "setup", "axis_1", "--yes")
    assert result.exit_code == 5, result.output + result.stderr
    assert "2 drives have no node ID" in result.stderr and "nothing was written" in \
        result.stderr and "Traceback" not in result.output
    with _network(url) as network:
        assert lss.configured_nodes(network, describe=False) == {}
        assert len(lss.find_unconfigured(network)) == 2


def test_a_dry_run_writes_nothing(cli, box):
    url, controls, serials = box
    controls.run("disconnect axis_2")
    result = cli("-p", PROFILE, "-t", url, "--json", "setup", "axis_1", "--dry-run")
    assert result.exit_code == 0, result.output + result.stderr
    doc = _doc(result)
    assert doc["dry_run"] and [s["action"] for s in doc["steps"]] == ["id", "store"]
    assert doc["joints"][0]["from"]["serial"] == serials["axis_1"]
    result = cli("-p", PROFILE, "-t", url, "setup", "--dry-run")
    assert result.exit_code == 0 and "planned (dry run" in result.stdout
    assert _serials_at(url) == {2: None, 3: None}


def test_drives_named_by_serial_are_set_up_all_connected_in_a_script(cli, variant):
    profile = variant(profile=lambda t: t.replace(
        "        address: 2\n", "        address: 2\n        params: {lss_serial: 0xA1}\n").replace(
        "        address: 3\n", "        address: 3\n        params: {lss_serial: 0xA0}\n"))
    with contextlib.ExitStack() as stack:
        served = serve_profile(stack, load_profile(str(profile)),
                               ServeOptions(factory_new=True), controls=Controls())
        url = served["endpoint"]
        result = cli("-p", profile, "-t", url, "--json", "setup", "--yes")  # no terminal
        assert result.exit_code == 0, result.output + result.stderr
        assert all(r["verified"] for r in _doc(result)["joints"])
        assert _serials_at(url) == {2: 0xA1, 3: 0xA0}


def test_setup_says_what_it_addresses(cli):
    result = cli("-p", "rrbot-gpio", "--sim", "setup", "--dry-run")
    assert result.exit_code == 2 and "nor a CANopen bus" in result.stderr
    result = cli("-p", PROFILE, "--sim", "--sim-fresh", "setup", "--in-place", "--yes")
    assert result.exit_code == 2 and "--in-place readdresses servos" in result.stderr
    result = cli("-p", PROFILE, "--sim", "--sim-fresh", "setup", "axis_1", "--yes",
                 "--factory-reset", "all", "--allow", "factory-reset")
    assert result.exit_code == 2 and "no factory reset" in result.stderr


def test_the_rate_found_is_the_links_and_a_new_bit_rate_is_taken_at_power_on(cli, box,
                                                                              variant):
    url, controls, _ = box  # the link at 1 Mbit/s
    controls.run("disconnect axis_2")
    profile = variant(profile=lambda t: t.replace("bitrate=1000000", "bitrate=500000"))
    result = cli("-p", profile, "-t", f"can0={url}", "--json", "setup", "axis_1", "--yes")
    assert result.exit_code == 0, result.output + result.stderr
    assert "bit rate 1000000 → 500000, taken at the next power-on" in result.stderr
    doc = _doc(result)
    [row] = doc["joints"]
    assert (row["from"]["baud"], row["to"]["baud"], row["verified"]) == \
        (1_000_000, 500_000, True)
    assert [(s["action"], s["at_baud"], s["value"]) for s in doc["steps"]] == [
        ("id", 1_000_000, 2), ("bit rate", 1_000_000, 500_000),
        ("store", 1_000_000, 500_000)]
