"""The robot as a library: ``from deltoctl import open_robot`` on every catalog profile's
simulated devices, through their real transports — no typer, no argv, no stdout."""

from __future__ import annotations

import subprocess
import sys

import pytest

import deltoctl
from deltoctl.errors import InvalidInput, Refused
from deltoctl.profile.catalog import catalog_names


@pytest.mark.parametrize("name", catalog_names())
def test_every_catalog_robot_opens_identifies_and_streams(name):
    with deltoctl.open_robot(name, sim=True) as robot:
        blocks = robot.identify()["blocks"]
        frames = list(robot.stream(rate=200, duration=0.1))
        values = robot.read()
    identified = {b["name"] for b in blocks}
    assert identified <= {m.name for m in robot.blocks}
    assert all(b["simulated"] for b in blocks)
    assert len(frames) >= 2
    assert values["system/connection_status"] == 1.0
    assert all(f.t_ns > 0 and "system/connection_status" in f.values for f in frames)


def test_a_hand_moves_within_its_limits_and_refuses_beyond_them():
    with deltoctl.open_robot("dg-5f-right", sim=True) as robot:
        report = robot.move({"rj_dg_2_2": 0.2})
        assert report["settled"]
        assert robot.read()["rj_dg_2_2/position"] == pytest.approx(0.2, abs=0.05)
        with pytest.raises(Refused) as refused:
            robot.move({"rj_dg_2_2": -0.3})
        assert refused.value.exit_code == 5
        assert robot.read()["rj_dg_2_2/position"] == pytest.approx(0.2, abs=0.05)


def test_jog_is_relative_and_names_are_checked():
    with deltoctl.open_robot("dg-5f-right", sim=True) as robot:
        start = robot.read()["rj_dg_2_2/position"]
        robot.jog({"rj_dg_2_2": 0.1})
        assert robot.read()["rj_dg_2_2/position"] == pytest.approx(start + 0.1, abs=0.05)
        with pytest.raises(InvalidInput, match=r"has no joint 'rj_dg_9_9'"):
            robot.jog({"rj_dg_9_9": 0.1})


def test_gpio_set_and_read_back():
    with deltoctl.open_robot("rrbot-gpio", sim=True) as robot:
        after = robot.set_gpio("digital_output1", 1.0)
        assert after["flange_digital_IOs/digital_output1"] == 1.0
        assert robot.gpio()["flange_digital_IOs/digital_output1"] == 1.0
        with pytest.raises(InvalidInput, match="no GPIO output"):
            robot.set_gpio("digital_output9", 1.0)


def test_a_robot_of_several_blocks_on_several_links():
    with deltoctl.open_robot("mh5", sim=True) as robot:
        result = robot.connect(count=3)
        names = robot.interfaces(["head_*/position"])
    assert len(result["blocks"]) >= 3  # two Dynamixel buses and the IMU
    assert {b["target"].split(":")[0] for b in result["blocks"]} >= {"serial", "i2c+tcp"}
    assert names and all(n.startswith("head_") for n in names)


def test_the_fixture_opens_a_simulated_robot_with_faults(deltoctl_robot):
    robot = deltoctl_robot("mh5", missing=("head_y",))
    assert any("head_y" in w for w in robot.warnings())
    assert "head_y/position" not in {k for k, v in robot.read().items() if v == v}


def test_bad_arguments_are_invalid_input():
    with deltoctl.open_robot("dg-5f-right", sim=True) as robot:
        with pytest.raises(InvalidInput, match="--rate"):
            next(robot.stream(rate=0))
        with pytest.raises(InvalidInput, match="matches no interface"):
            robot.interfaces(["nothing_*"])
    with pytest.raises(InvalidInput, match="sim"), \
            deltoctl.open_robot("dg-5f-right", sim={"no_such_fault": 1}):
        pass


def test_the_library_imports_no_terminal_code():
    code = ("import sys, deltoctl; deltoctl.open_robot; "
            "print(sorted(m for m in ('typer', 'click', 'rich') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_config_round_trip_through_the_library(tmp_path):
    from deltoctl.app.config import dump_yaml

    with deltoctl.open_robot("mh5", sim=True) as robot:
        doc = robot.config_snapshot()
        path = tmp_path / "mh5.yaml"
        path.write_text(dump_yaml(doc))
        assert robot.config_diff(path) == []
        doc["blocks"]["upper_body"]["parts"]["head_y"]["Max Position Limit"]["value"] = 3000
        path.write_text(dump_yaml(doc))
        with pytest.raises(Refused, match="--allow"):
            robot.config_restore(path)
        assert robot.registers("head_y", ["Max Position Limit"])["items"][0]["value"] != 3000


def test_record_through_the_library_on_several_links(tmp_path):
    from deltoctl.record.reader import describe

    with deltoctl.open_robot("mh5", sim=True) as robot:
        result = robot.record(tmp_path / "mh5.mcap", rate=100, duration=0.3)
    assert result["messages"]["/joint_states"] >= 10
    assert describe(tmp_path / "mh5.mcap")["topics"]


def test_home_runs_routines_and_poses_on_a_cell_of_several_blocks():
    with deltoctl.open_robot("bioscara-dg-3f-m", sim=True) as robot:
        report = robot.home()
        values = robot.read()
    outcomes = [j["outcome"] for b in report["blocks"] for j in b["joints"].values()
                if "outcome" in j]
    assert outcomes and all(outcomes)
    assert report["settled"] and not report["cannot_home"]
    assert all(abs(values[f"{j}/position"]) < 0.05
               for b in report["blocks"] for j, r in b["joints"].items() if "target" in r)


def test_a_recorded_jog_replays_through_the_library(tmp_path):
    from deltoctl.app.recording import recorded_moves

    path = tmp_path / "jog.mcap"
    with deltoctl.open_robot("dg-5f-right", sim=True) as robot:
        recorded_moves(robot.system, path, lambda: robot.jog({"rj_dg_2_2": 0.2}))
    with deltoctl.open_robot("dg-5f-right", sim=True) as robot:
        report = robot.replay(path, tolerance=0.1)
    assert report["commands"] > 10 and report["on"] == "simulator"
    assert report["joints"]["rj_dg_2_2"]["max"] < 0.1 and not report["exceeded"]


def test_a_jog_from_an_unknown_position_is_refused_before_anything_moves():
    from deltoctl.errors import DeviceError

    with deltoctl.open_robot("mh5", sim={"missing": ("head_y",)}) as robot, \
            pytest.raises(DeviceError, match="position of head_y is not known"):
        robot.jog({"head_y": 0.05})


def test_servo_verbs_take_a_group_and_jogs_a_quantity():
    with deltoctl.open_robot("mh5", sim=True) as robot:
        assert robot.torque("head", False) == ["head_p", "head_y"]
        start = robot.read()["head_y/position"]
        assert robot.jog_targets({"head_y": "2deg"})["head_y"] == pytest.approx(
            start + 0.0349066, abs=1e-6)
        with pytest.raises(InvalidInput, match="neither a joint nor a group"):
            robot.reboot("hed")


def test_a_name_of_no_joint_lists_the_groups_the_profile_has():
    from deltoctl.app.robot import select_joints
    from deltoctl.profile.catalog import load_profile

    mh5 = r"\(groups: arms, head, left_arm, left_leg, legs, right_arm, right_leg, all\)$"
    with pytest.raises(InvalidInput, match=mh5):
        select_joints(load_profile("mh5"), "zzz", "torque")
    with pytest.raises(InvalidInput, match=r"of open-manipulator-x \(groups: all\)$"):
        select_joints(load_profile("open-manipulator-x"), "zzz", "torque")


def test_a_restore_tells_its_caller_what_it_will_write_and_a_refusal_carries_its_plan(
        tmp_path):
    from deltoctl.app.config import dump_yaml

    with deltoctl.open_robot("mh5", sim=True) as robot:
        doc = robot.config_snapshot()
        before = doc["blocks"]["upper_body"]["parts"]["head_y"]["Return Delay Time"]["value"]
        doc["blocks"]["upper_body"]["parts"]["head_y"]["Return Delay Time"]["value"] = 7
        path = tmp_path / "mh5.yaml"
        path.write_text(dump_yaml(doc))
        told = []

        def no(what):
            told.append(what)
            raise Refused("not now")

        with pytest.raises(Refused, match="not now"):
            robot.config_restore(path, confirm=no)
        assert told and "upper_body/head_y" in told[0]
        assert robot.registers("head_y", ["Return Delay Time"])["items"][0]["value"] == before
        rows = robot.config_restore(path, confirm=told.append)
        assert [r["status"] for r in rows if r["item"] == "Return Delay Time"] == ["verified"]
        doc["blocks"]["upper_body"]["parts"]["head_y"]["Max Position Limit"]["value"] = 3000
        path.write_text(dump_yaml(doc))
        with pytest.raises(Refused) as refused:
            robot.config_restore(path, confirm=told.append)
    assert len(told) == 2  # a refused plan asks no one
    assert [r["status"] for r in refused.value.rows if r["item"] == "Max Position Limit"] \
        == ["refused"]


def test_a_jog_is_planned_in_words_and_checked_before_it_moves():
    with deltoctl.open_robot("dg-5f-right", sim=True) as robot:
        start = robot.read()["rj_dg_2_2/position"]
        targets, moves = robot.plan_jog([("rj_dg_2_2", "5deg")])
        assert targets["rj_dg_2_2"] == pytest.approx(start + 0.0873, abs=1e-3)
        assert moves[0].startswith("rj_dg_2_2 (") and "(+5.0" in moves[0]
        with pytest.raises(Refused):
            robot.plan_jog([("rj_dg_2_2", "-90deg")], to=None)
        assert robot.read()["rj_dg_2_2/position"] == pytest.approx(start, abs=0.01)


def test_cycles_feed_sinks_and_watch_the_links():
    from deltoctl.core.runner import Sink

    class Count(Sink):
        frames = 0

        def frame(self, t_ns, values):
            self.frames += 1

    with deltoctl.open_robot("dg-5f-right", sim=True) as robot:
        count = Count()
        loop, links = robot.cycles(100, 0.2, [count])
        links.finish()
        assert count.frames == loop["cycles"] >= 2
        assert robot.loop_warnings(100, loop) == []
        with pytest.raises(InvalidInput, match="--rate"):
            robot.cycles(0, 0.2, [])
