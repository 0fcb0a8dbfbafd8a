"""What the family tests share: the toy family (tests/toyfamily/) registered in this process,
and a two-block profile of it."""

from __future__ import annotations

import pytest

from deltoctl import registry
from tests.toyfamily import FAMILY, TRANSPORT

PROFILE = """\
name: toy-robot
buses: {left: "toy://127.0.0.1:9", right: "toy://127.0.0.1:9"}
ros2_control:
  - name: toy_left
    plugin: toy_hardware/ToySystem
    bus: left
    joints:
      - {name: l1, command_interfaces: [position], state_interfaces: [position]}
      - {name: l2, command_interfaces: [position], state_interfaces: [position]}
  - name: toy_right
    plugin: toy_hardware/ToySystem
    bus: right
    joints:
      - {name: r1, command_interfaces: [position], state_interfaces: [position]}
"""


@pytest.fixture
def toy(tmp_path):
    """The toy family registered in this process, and its profile's path."""
    registry.register(FAMILY)
    registry.register_transport("toy", TRANSPORT)
    path = tmp_path / "toy-robot.yaml"
    path.write_text(PROFILE)
    yield str(path)
    registry.unregister(FAMILY.name)
    registry.unregister_transport("toy")
