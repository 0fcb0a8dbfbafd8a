"""The plugin on a real SocketCAN interface (vcan0), where the machine has one."""

from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not Path("/sys/class/net/vcan0").exists(),
                                reason="no vcan0 (ip link add dev vcan0 type vcan)")


def test_identify_over_vcan(cli):
    import canopen
    from conftest import PROFILE

    from deltoctl_canopen import eds
    from deltoctl_canopen.emulator import EmulatedDrive, NodeFaults
    from deltoctl_canopen.nodes import GENERIC_EDS

    network = canopen.Network()
    network.connect(interface="socketcan", channel="vcan0")
    try:
        for node_id in (2, 3):
            EmulatedDrive(network, node_id, eds.load(GENERIC_EDS, node_id), NodeFaults()).boot()
        result = cli("-p", PROFILE, "-t", "can://socketcan/vcan0", "identify")
        assert result.exit_code == 0, result.stderr
    finally:
        network.disconnect()
