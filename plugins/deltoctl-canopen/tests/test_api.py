"""The robot library on CANopen drives, and deltoctl without the plugin."""

import json
import subprocess
import sys

import pytest
from conftest import PROFILE
from deltoctl import open_robot

HIDE_PLUGIN = """
import importlib.metadata as md, os, sys, tempfile
os.environ["XDG_CACHE_HOME"] = tempfile.mkdtemp()  # entry points read, not from the cache
real = md.entry_points
def entry_points(**kw):
    found = real(**kw)
    return type(found)(ep for ep in found
                       if not (ep.value.startswith("deltoctl_canopen") or ep.name == "localhub"))
md.entry_points = entry_points
class Hidden:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] == "deltoctl_canopen":
            raise ModuleNotFoundError(name)
sys.meta_path.insert(0, Hidden())
from deltoctl.cli.main import main
sys.argv = ["deltoctl", *sys.argv[1:]]
main()
"""


def test_open_robot_moves_and_identifies():
    with open_robot(str(PROFILE), sim=True) as robot:
        ident = robot.identify()
        text = json.dumps(ident, default=str)
        assert "deltoctl generic CiA 402 drive" in text
        robot.move({"axis_1": 0.2, "axis_2": -0.1})
        values = robot.read()
        assert abs(values["axis_1/position"] - 0.2) < 0.01
        assert abs(values["axis_2/position"] + 0.1) < 0.01


def deltoctl_without_plugin(*args):
    return subprocess.run([sys.executable, "-c", HIDE_PLUGIN, *args], capture_output=True,
                          text=True, timeout=120)


def test_deltoctl_without_the_plugin_lists_and_runs_everything_else():
    listed = deltoctl_without_plugin("profile", "list", "--json")
    assert listed.returncode == 0, listed.stderr
    assert "dg-5f-right" in listed.stdout and "warning" not in listed.stderr
    run = deltoctl_without_plugin("-p", "dg-5f-right", "--sim", "--json", "identify")
    assert run.returncode == 0, run.stderr
    # a CANopen profile is then a block no family drives: one clear error, no traceback
    refused = deltoctl_without_plugin("-p", str(PROFILE), "--sim", "identify")
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert "canopen" in refused.stderr


def test_an_sdo_abort_is_a_device_fault_with_its_abort_code():
    from deltoctl import DeviceFault

    refusal = r"axis_1 \(node \d+\) refused to write 1 to 0x1010:01"
    with open_robot(str(PROFILE), sim=True) as robot, \
            pytest.raises(DeviceFault, match=refusal) as fault:
        robot.write_register("axis_1", "0x1010:01", 1)  # without the "save" signature
    assert fault.value.code == 0x08000020
    assert fault.value.exit_code == 1


def test_a_node_that_never_answers_is_no_answer():
    from deltoctl import NoAnswer

    with open_robot(str(PROFILE), sim={"missing": ("axis_2",)}) as robot, \
            pytest.raises(NoAnswer, match=r"axis_2 \(node \d+\) does not answer"):
        robot.registers("axis_2", ["0x6041"])


def test_a_can_bus_gone_while_in_use_is_link_lost():
    from deltoctl import LinkLost

    with open_robot(str(PROFILE), sim=True) as robot, \
            pytest.raises(LinkLost, match=r"axis_1 \(node \d+\) did not answer a read of "
                                          r"0x6041:00 \(local CAN hub lost"):
        robot.blocks[0].driver.network.bus.shutdown()  # as an adapter that is unplugged
        robot.registers("axis_1", ["0x6041"])
