"""`profile validate` shows what ros2_control lets through but deltoctl warns about (exit 3),
and --strict makes those warnings errors (exit 2)."""

from __future__ import annotations

import json

URDF = """<?xml version="1.0"?>
<robot name="r">
  <link name="base"/><link name="l1"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <limit lower="-1" upper="1"/></joint>
  <ros2_control name="b" type="system">
    <hardware><plugin>mock_components/GenericSystem</plugin></hardware>
    <joint name="j1"><command_interface name="position"/><state_interface name="position"/>
    </joint>
  </ros2_control>
</robot>
"""


def test_warnings_then_strict(cli, tmp_path):
    path = tmp_path / "r.urdf"
    path.write_text(URDF)
    result = cli("--json", "profile", "validate", str(path))
    assert result.exit_code == 3, result.stderr
    [report] = json.loads(result.stdout)["result"]
    assert report["ok"] and any("effort" in w for w in report["warnings"])
    result = cli("profile", "validate", "--strict", str(path))
    assert result.exit_code == 2 and "effort" in result.stderr
    assert cli("profile", "validate", "dg-5f-right").exit_code == 0
