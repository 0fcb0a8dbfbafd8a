"""A recording is untrusted input: replayed on a device, the limits in force are those of the
profile the user names (-p) or of the catalog's profile of the recorded name — never the
recording's own — and the device is the one -t (or --sim) names, never a bus URL of the file.
Against a real emulated DG-5F-R on loopback, and a listening port standing for another robot
the recording points at."""

from __future__ import annotations

import copy
import json
import math
import socket
import threading
import time

import pytest

from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile
from tests.app.test_replay import _recording_with
from tests.conftest import eventually

JOINT = "rj_dg_2_2"  # 0°..115° on a DG-5F-R (2.0071 rad): the emulator's stop is there
INDEX = 5  # its motor


@pytest.fixture
def hand():
    """An emulated DG-5F-R with the catalog's joint limits as its hard stops; records the
    largest duty it was ever sent."""
    with DeltoServer(firmware_for_profile(load_profile("dg-5f-right"))) as server:
        firmware = server.firmware
        firmware.pushed = 0
        handle = firmware.handle

        def watch(data):
            reply = handle(data)
            firmware.pushed = max(firmware.pushed, *map(abs, firmware.duty))
            return reply

        firmware.handle = watch
        yield server


@pytest.fixture
def elsewhere():
    """A TCP port standing for another robot: ``(url, connections accepted)``."""
    server = socket.create_server(("127.0.0.1", 0))
    accepted: list[socket.socket] = []

    def accept():
        while True:
            try:
                accepted.append(server.accept()[0])
            except OSError:
                return

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{server.getsockname()[1]}", accepted
    server.shutdown(socket.SHUT_RDWR)
    server.close()
    thread.join(timeout=5)
    for conn in accepted:
        conn.close()


def _profile(url: str, upper: float | None = None, cap: float | None = None, name=None,
             narrow: str | None = None):
    """The catalog's DG-5F-R as a recording would carry it, its bus at ``url``; ``upper``
    widens JOINT's limit, ``cap`` the current cap, ``narrow`` halves another joint's range."""
    profile = copy.deepcopy(load_profile("dg-5f-right"))
    profile.buses["gripper"] = url
    host, port = url.removeprefix("tcp://").split(":")
    profile.hardware[0].params.update(delto_ip=host, delto_port=port)
    if upper is not None:
        profile.component(JOINT).limits.upper = upper
    if cap is not None:
        profile.safety.current_cap = cap
    if narrow is not None:
        profile.component(narrow).limits.upper /= 2
    if name is not None:
        profile.name, profile.model = name, "X-1"
    return profile


def _push(profile, seconds: float, to: float, effort: float = 0.15):
    """Rows every 5 ms: JOINT's position command ramping from 0 to ``to`` with ``effort``
    (within the catalog's current cap), and its recorded position following it."""
    nan = float("nan")
    base = {f"{j.name}/{k}": 0.0 for j in profile.joints() for k in ("position", "velocity")}
    blank = {f"{JOINT}/{k}_command": nan for k in ("position", "velocity", "effort")}
    t0, n = time.time_ns(), int(seconds / 0.005)
    rows = []
    for i in range(n):
        at = to * i / (n - 1)
        rows.append((t0 + i * 5_000_000, {**base, **blank, f"{JOINT}/position": at,
                                          f"{JOINT}/position_command": at,
                                          f"{JOINT}/effort_command": effort}))
    return rows


def _untouched(hand) -> bool:
    return hand.firmware.pushed == 0 and hand.firmware.position[INDEX] == 0.0


def test_a_recording_that_widens_the_limits_is_refused_on_a_device(cli, hand, elsewhere,
                                                                    tmp_path):
    """Its profile takes JOINT to 3.0 rad and the cap to 3000 mA, and its commands go to
    2.8 rad: on the device, the catalog's limits apply (jog --to 2.8 is refused there too),
    the looser profile is named and refused, and nothing is sent."""
    url, accepted = elsewhere
    wide = _profile(url, upper=3.0, cap=3000)
    out = tmp_path / "wide.mcap"
    _recording_with(out, wide, _push(wide, 1.0, 2.8, effort=3.0))  # within 3000 mA
    for profile in ((), ("-p", "dg-5f-right")):  # the catalog's by the recorded name, or -p
        result = cli(*profile, "replay", str(out), "--device", "-t", hand.endpoint, "--yes")
        assert result.exit_code == 5, result.stderr
        assert "its profile is looser than dg-5f-right" in result.stderr
        assert f"{JOINT} upper limit 3 recorded, 2.0071 in force" in result.stderr
        assert "safety.current_cap 3000 recorded, 150 in force" in result.stderr
        assert "nothing moved" in result.stderr and "Traceback" not in result.stderr
    assert _untouched(hand)  # never pushed: nowhere near its stop
    assert cli("-p", "dg-5f-right", "-t", hand.endpoint, "jog", JOINT, "--to", "2.8",
               "--yes").exit_code == 5
    # the same commands under a profile as wide as the recording's: refused one by one
    only_commands = tmp_path / "commands.mcap"
    _recording_with(only_commands, _profile(url), _push(wide, 1.0, 2.8))
    result = cli("replay", str(only_commands), "--device", "-t", hand.endpoint, "--yes")
    assert result.exit_code == 5, result.stderr
    assert f"{JOINT} target" in result.stderr and "outside its limits [0.0000, 2.0071]" \
        in result.stderr
    assert _untouched(hand)
    assert accepted == []  # the recording's bus URL was never opened


def test_the_recordings_bus_urls_never_choose_a_device(cli, hand, elsewhere, tmp_path):
    url, accepted = elsewhere
    same = _profile(url)
    out = tmp_path / "elsewhere.mcap"
    _recording_with(out, same, _push(same, 0.1, 0.05))
    for args in ((), ("-p", "dg-5f-right")):
        result = cli(*args, "replay", str(out), "--device", "--yes")
        assert result.exit_code == 2, result.stderr
        assert "-t gripper=URL" in result.stderr and "never takes a device" in result.stderr
    assert accepted == [] and _untouched(hand)
    # -t names the device: the replay runs there, and only there
    result = cli("replay", str(out), "--device", "-t", hand.endpoint, "--yes", "--json",
                 "--max-deviation", "100")
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)["result"]
    assert report["on"] == "device" and report["target"] == hand.endpoint
    assert hand.firmware.pushed > 0 and accepted == []
    assert eventually(lambda: hand.firmware.duty == [0] * 20)


def test_device_sim_rehearses_under_the_catalogs_limits(cli, elsewhere, tmp_path):
    url, accepted = elsewhere
    wide = _profile(url, upper=3.0, cap=3000)
    out = tmp_path / "wide.mcap"
    _recording_with(out, wide, _push(wide, 1.0, 2.8))
    refused = cli("replay", str(out), "--device", "--sim")
    assert refused.exit_code == 5, refused.stderr
    assert "its profile is looser than dg-5f-right" in refused.stderr
    # on the recording's own simulators (no --device), its own profile: a rehearsal
    jogged = tmp_path / "jog.mcap"
    assert cli("-p", "dg-5f-right", "--sim", "jog", JOINT, "10deg", "--yes", "--record",
               str(jogged)).exit_code == 0
    result = cli("--yes", "replay", str(jogged), "--device", "--sim", "--json")
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["result"]["on"] == "simulator"
    assert accepted == []


def test_a_recorded_profile_not_in_the_catalog_needs_p(cli, hand, elsewhere, tmp_path):
    url, accepted = elsewhere
    renamed = _profile(url, name="my-hand")
    out = tmp_path / "mine.mcap"
    _recording_with(out, renamed, _push(renamed, 0.1, 0.05))
    result = cli("replay", str(out), "--device", "-t", hand.endpoint, "--yes")
    assert result.exit_code == 2, result.stderr
    assert "'my-hand'" in result.stderr and "not in the catalog" in result.stderr
    assert "-p PROFILE" in result.stderr and _untouched(hand)
    named = cli("-p", "dg-5f-right", "replay", str(out), "--device", "-t", hand.endpoint,
                "--yes", "--max-deviation", "100")
    assert named.exit_code == 0, named.stderr
    assert hand.firmware.pushed > 0 and accepted == []


def test_a_tighter_recorded_profile_is_shown_and_replayed(cli, hand, elsewhere, tmp_path):
    url, accepted = elsewhere
    tight = _profile(url, narrow="rj_dg_3_2")
    out = tmp_path / "tight.mcap"
    _recording_with(out, tight, _push(tight, 0.1, 0.05))
    result = cli("replay", str(out), "--device", "-t", hand.endpoint, "--yes",
                 "--max-deviation", "100")
    assert result.exit_code == 3, result.stderr
    assert "the recording's profile differs from dg-5f-right, whose limits apply" \
        in result.stderr
    upper = math.radians(112)
    assert f"rj_dg_3_2 upper limit {upper / 2:.4f} recorded, {upper:.4f} in force" \
        in result.stderr
    assert hand.firmware.pushed > 0 and accepted == []
