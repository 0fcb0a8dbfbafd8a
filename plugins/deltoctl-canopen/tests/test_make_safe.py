"""Setting the blocks safe (what the fleet's agent does after killing a motion verb) quick
stops every drive, though this session enabled none: the killed process left one enabled."""

from conftest import PROFILE
from deltoctl import open_robot

from deltoctl_canopen.drive import ENABLED, QUICK_STOP, SOD


def test_set_safe_quick_stops_a_drive_another_session_left_enabled(drives):
    with open_robot(str(PROFILE), drives.url) as mover:
        assert mover.system.move({"axis_1": 0.2}).settled  # axis_1 left enabled, holding
        states = {n: d.drive.state for n, d in drives.drives.items()}
        assert ENABLED in states.values()
        with open_robot(str(PROFILE), drives.url) as agent:
            agent.system.stop()  # its own stop: it enabled nothing, so it sends nothing
            agent.read()
            assert {n: d.drive.state for n, d in drives.drives.items()} == states
            agent.system.make_safe()
            agent.read()
            # quick stopped: held, then Switch On Disabled as its quick stop option code says
            assert {d.drive.state for d in drives.drives.values()} <= {QUICK_STOP, SOD}
