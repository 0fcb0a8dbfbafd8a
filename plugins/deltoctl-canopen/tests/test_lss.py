"""From the box to ``identify``: drives served factory-new (no node ID), found and given the
profile's node IDs over LSS through canopen's LssMaster — as ``deltoctl setup JOINT`` does it
(deltoctl.app.setup), and by ``lss.assign`` at a drive's LSS address —, checked by canopen's
own SDO client and by deltoctl identify; and ``deltoctl scan`` on the CAN bus."""

import contextlib
import json

import canopen
import pytest
from conftest import PROFILE
from deltoctl.errors import NoAnswer, ProfileError, Refused
from deltoctl.profile.catalog import load_profile
from deltoctl.sim.controls import Controls
from deltoctl.sim.serve import ServeOptions, serve_profile

from deltoctl_canopen import lss
from deltoctl_canopen.transport import open_bus, parse_can_url

JOINTS = ("axis_1", "axis_2")


class Served:
    """A profile's drives served in this process, the control lines, and canopen's own
    network on their bus."""

    def __init__(self, stack: contextlib.ExitStack, profile=PROFILE, **options) -> None:
        self.profile = load_profile(str(profile))
        self.controls = Controls()
        result = serve_profile(stack, self.profile, ServeOptions(**options),
                               controls=self.controls)
        self.url, self.serials = result["endpoint"], result["blocks"]["axes"]["lss_serials"]
        self.network = canopen.Network(open_bus(parse_can_url(self.url)))
        self.network.connect()
        stack.callback(self.network.disconnect)

    def set_up(self, joint: str) -> dict:
        """``joint``'s drive set up as ``deltoctl setup JOINT`` does it: its row."""
        from deltoctl.app.setup import open_setup

        with open_setup(self.profile, [f"can0={self.url}"]) as run:
            return run.apply_one(joint, run.plan_one(joint)).joints[0]

    def only_unconfigured(self) -> lss.Identity:
        [identity] = lss.find_unconfigured(self.network)
        return identity


@pytest.fixture
def box():
    with contextlib.ExitStack() as stack:
        yield lambda profile=PROFILE, **options: Served(stack, profile, factory_new=True,
                                                        **options)


def serial_at(network, node_id):
    """0x1018:4 read at a node ID with canopen's own client (None: nothing answers)."""
    node = network.add_node(node_id)
    try:
        return int.from_bytes(node.sdo.upload(0x1018, 4), "little")
    except canopen.SdoCommunicationError:
        return None
    finally:
        del network[node_id]


def test_factory_new_drives_answer_lss_only(box):
    served = box()
    assert lss.configured_nodes(served.network) == {}
    found = lss.find_unconfigured(served.network)
    assert sorted(i.serial for i in found) == sorted(served.serials.values())
    assert found == sorted(found, key=lambda i: i.parts)
    assert {(i.vendor, i.product) for i in found} == {(0xDE7, 0x40201)}
    assert lss.find_unconfigured(served.network) == found  # left as they were


def test_from_the_box_to_identify_one_drive_at_a_time(box, cli):
    served = box()
    served.controls.run("disconnect all")
    done = []
    for joint in JOINTS:
        served.controls.run(f"connect {joint}")
        done.append(served.set_up(joint))
    assert [(d["joint"], d["to"]["id"], d["status"], d["verified"]) for d in done] == \
        [("axis_1", 2, "set", True), ("axis_2", 3, "set", True)]
    assert serial_at(served.network, 2) == served.serials["axis_1"]
    assert serial_at(served.network, 3) == served.serials["axis_2"]
    result = cli("-p", PROFILE, "-t", served.url, "identify")
    assert result.exit_code == 0, result.output + result.stderr
    # stored: powered off and on, each comes back at its node ID
    served.controls.run("disconnect all")
    served.controls.run("connect all")
    assert serial_at(served.network, 2) == served.serials["axis_1"]
    assert [served.set_up(j)["status"] for j in JOINTS] == ["already set", "already set"]


def test_drives_named_by_serial_are_set_up_all_connected(box, variant):
    profile = variant(profile=lambda t: t.replace(
        "        address: 2\n", "        address: 2\n        params: {lss_serial: 0xA1}\n").replace(
        "        address: 3\n", "        address: 3\n        params: {lss_serial: 0xA0}\n"))
    served = box(profile)
    assert served.serials == {"axis_1": 0xA1, "axis_2": 0xA0}
    for joint in JOINTS:
        served.set_up(joint)
    assert (serial_at(served.network, 2), serial_at(served.network, 3)) == (0xA1, 0xA0)


def test_two_drives_nobody_named_are_not_guessed(box):
    served = box()
    with pytest.raises(Refused, match="2 drives have no node ID"):
        served.set_up("axis_1")
    assert lss.configured_nodes(served.network, describe=False) == {}
    assert len(lss.find_unconfigured(served.network)) == 2


def test_no_drive_connected_and_a_node_id_taken(box):
    served = box()
    served.controls.run("disconnect axis_2")
    served.set_up("axis_1")
    with pytest.raises(NoAnswer, match="axis_2: no drive without a node ID answers"):
        served.set_up("axis_2")
    with pytest.raises(NoAnswer, match="no drive answers at LSS address"):
        lss.assign(served.network, lss.Identity(0xDE7, 0x40201, 0x10002, 0x1234), 5)
    taken = lss.Step("axis_2", 2, 1_000_000, serial=0x1234)
    with pytest.raises(Refused, match="node 2 is taken"):
        lss.locate(served.network, taken)


def test_a_node_id_not_stored_is_lost_at_power_off(box):
    served = box()
    served.controls.run("disconnect axis_2")
    done = lss.assign(served.network, served.only_unconfigured(), 9, store=False)
    assert done["identity"]["serial"] == served.serials["axis_1"] and done["was"] is None
    served.controls.run("disconnect axis_1")
    served.controls.run("connect axis_1")
    assert serial_at(served.network, 9) is None
    assert [i.serial for i in lss.find_unconfigured(served.network)] == \
        [served.serials["axis_1"]]


def test_a_configured_drive_moves_to_another_node_id(box):
    served = box()
    served.controls.run("disconnect axis_2")
    identity = served.only_unconfigured()
    lss.assign(served.network, identity, 9)
    done = lss.assign(served.network, identity, 12, bitrate=1_000_000)
    assert done["was"] == 9 and serial_at(served.network, 12) == served.serials["axis_1"]
    assert serial_at(served.network, 9) is None


def test_bad_serial_param_and_bad_control_lines(box, variant):
    from deltoctl.errors import InvalidInput

    profile = variant(profile=lambda t: t.replace(
        "        address: 2\n", "        address: 2\n        params: {lss_serial: twelve}\n"))
    with pytest.raises(ProfileError, match="lss_serial must be a 32-bit serial number"):
        box(profile)
    served = box()
    with pytest.raises(InvalidInput, match="takes one joint of a CANopen drive or all"):
        served.controls.run("connect axis_9")
    with pytest.raises(InvalidInput, match="LSS sets no bit rate"):
        lss.assign(served.network, lss.Identity(0xDE7, 0x40201, 0x10002, 1), 5,
                   bitrate=33_000)
    with pytest.raises(InvalidInput, match="no servo joint 'axis_9'"):
        served.set_up("axis_9")


def test_scan_lists_nodes_and_drives_without_a_node_id(box, cli):
    served = box()
    served.controls.run("disconnect axis_2")
    served.set_up("axis_1")
    served.controls.run("connect axis_2")
    result = cli("--json", "scan", served.url, "--wait", "0.5")
    assert result.exit_code == 0, result.output + result.stderr
    found = json.loads(result.stdout)["result"]["servos"]
    assert [(f["id"], f["protocol"]) for f in found] == \
        [(2, "CANopen"), (None, "CANopen LSS (no node ID)")]
    assert found[0]["model"] == "deltoctl generic CiA 402 drive"
    assert found[1]["identity"]["serial"] == served.serials["axis_2"]
    result = cli("scan", served.url, "--wait", "0.5")
    assert "none  " in result.stdout and "2 answered on can://localhub/" in result.stdout


def test_scan_of_an_empty_bus_is_unreachable(cli):
    from deltoctl_canopen.hub import HubServer

    with HubServer() as hub:
        result = cli("scan", f"can://localhub/{hub.channel}")
    assert result.exit_code == 4 and "nothing answers on can://localhub/" in result.stderr
    result = cli("scan", "can://localhub/10.0.0.1:5")
    assert result.exit_code == 2 and "loopback" in result.stderr


def test_sim_serve_factory_new_and_its_control_lines(cli):
    import subprocess

    from conftest import DELTOCTL

    proc = subprocess.Popen([*DELTOCTL, "sim", "serve", str(PROFILE), "--factory-new", "--json"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        served = json.loads(proc.stdout.readline())
        assert served["controls"] == ["connect", "disconnect"]
        proc.stdin.write("disconnect axis_2\n")
        proc.stdin.flush()
        assert json.loads(proc.stdout.readline())["reply"] == "canopen: axis_2 disconnected"
        result = cli("--json", "scan", served["endpoint"], "--wait", "0.5")
        assert result.exit_code == 0, result.output + result.stderr
        [drive] = json.loads(result.stdout)["result"]["servos"]
        assert drive["id"] is None and drive["identity"]["serial"] == \
            served["blocks"]["axes"]["lss_serials"]["axis_1"]
    finally:
        proc.terminate()
        proc.wait(5)
    result = cli("-p", PROFILE, "--sim", "--sim-option", "factory_new", "identify")
    assert result.exit_code == 4  # no node ID yet: nothing answers SDO


def test_a_stored_bit_rate_is_taken_at_the_next_power_on(box):
    served = box()
    served.controls.run("disconnect axis_2")
    identity = served.only_unconfigured()
    lss.assign(served.network, identity, 4, bitrate=500_000)
    assert serial_at(served.network, 4) == served.serials["axis_1"]  # still at 1 Mbit/s
    served.controls.run("disconnect axis_1")
    served.controls.run("connect axis_1")  # at 500 kbit/s now, on a bus at 1 Mbit/s
    assert serial_at(served.network, 4) is None
    with pytest.raises(NoAnswer):  # nor does it hear LSS
        lss.assign(served.network, identity, 5)
