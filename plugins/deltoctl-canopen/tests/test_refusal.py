"""A move or jog the envelope refuses has no effect on a drive: no command and no quick stop,
through the library and through the CLI. The drives count every write they are sent (each
RPDO frame, each SDO download)."""

import threading

import pytest
from conftest import PROFILE
from deltoctl import open_robot
from deltoctl.errors import Refused

RPDO_BASES = (0x200, 0x300, 0x400, 0x500)


class Writes:
    """Every write a drive of ``bus`` receives: its RPDO frames and SDO downloads."""

    def __init__(self, bus) -> None:
        self.frames: list[tuple[int, bytes]] = []
        self.lock = threading.Lock()
        for node in bus.drives:
            for can_id in (*(base + node for base in RPDO_BASES), 0x600 + node):
                bus.network.subscribe(can_id, self.heard)

    def heard(self, can_id: int, data: bytes, timestamp: float) -> None:
        download = can_id & 0x780 == 0x600 and data[0] >> 5 == 1
        if can_id & 0x780 != 0x600 or download:
            with self.lock:
                self.frames.append((can_id, bytes(data)))

    def count(self) -> int:
        with self.lock:
            return len(self.frames)


def test_a_refused_move_sends_an_enabled_drive_nothing(drives):
    writes = Writes(drives)
    with open_robot(str(PROFILE), drives.url) as robot:
        # the System's move leaves axis_1 enabled, holding its target (a caller's stop ends it)
        assert robot.system.move({"axis_1": 0.2}).settled
        robot.read()
        before = writes.count()
        for call in (lambda: robot.move({"axis_1": 0.3, "axis_2": 2.0}),
                     lambda: robot.jog({"axis_1": "40deg"}),
                     lambda: robot.move({"axis_1": 0.1}, velocity=5.0)):
            with pytest.raises(Refused):
                call()
        robot.read()
        assert writes.count() == before
        robot.system.stop()  # what the caller's stop sends: a quick stop, one RPDO frame
        robot.read()
        assert writes.count() == before + 1


def test_a_refused_jog_on_the_cli_sends_the_drives_nothing(cli, drives):
    writes = Writes(drives)
    for args in (["jog", "axis_2", "100deg"], ["jog", "axis_1", "40deg"],
                 ["jog", "axis_1", "5deg", "--velocity", "5"]):
        result = cli("-p", PROFILE, "-t", drives.url, *args, "--yes")
        assert result.exit_code == 5, result.output + result.stderr
    # the start-up's SDO writes (the bus file's), then nothing for the jogs
    startup = [f for f in writes.frames if f[0] & 0x780 == 0x600]
    assert writes.count() == len(startup)
    assert not any(data[1:3] == b"\x40\x60" for _, data in startup)  # no controlword
