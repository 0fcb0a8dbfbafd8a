"""Strict targets: a Dynamixel bus at a rate its servos cannot run, or a URL that cannot be
read (``tcp://[::1``), is one usage error naming it (exit 2), before any port is opened."""

from __future__ import annotations

import json

import pytest

from deltoctl.families.dynamixel import parse_bus_url
from deltoctl.families.dynamixel.control_table import BAUD_RATES

RATES = "9600, 57600, 115200, 1000000, 2000000, 3000000, 4000000, 4500000"


def _mh5_targets(buses: dict[str, str], **bauds: int) -> list[str]:
    """-t BUS=URL for each served bus, with the baud of some replaced."""
    args = []
    for bus, url in buses.items():
        if bus in bauds:
            path, _, query = url.partition("?")
            rest = "&".join(kv for kv in query.split("&") if not kv.startswith("baud="))
            url = f"{path}?baud={bauds[bus]}" + (f"&{rest}" if rest else "")
        args += ["-t", f"{bus}={url}"]
    return args


def test_the_rates_are_the_baud_rate_registers_table():
    assert ", ".join(str(b) for b in sorted(BAUD_RATES.values())) == RATES
    for baud in BAUD_RATES.values():
        assert parse_bus_url(f"serial:///dev/ttyUSB0?baud={baud}")[1] == baud


def test_a_rate_the_servos_cannot_run_is_refused_before_the_port_opens(cli, deltoctl_sim,
                                                                       tmp_path):
    buses = deltoctl_sim.buses("mh5")
    log = tmp_path / "links.ndjson"
    result = cli("-p", "mh5", "--log-file", str(log), *_mh5_targets(buses, upper_body=123),
                 "connect")
    assert result.exit_code == 2, result.stderr
    assert "cannot run at 123 baud" in result.stderr and RATES in result.stderr
    assert result.stderr.count("\n") == 1  # one line, no traceback
    opened = [json.loads(line)["msg"] for line in log.read_text().splitlines()]
    assert not any("open at" in msg for msg in opened), opened  # no port was opened


def test_the_refusal_in_json(cli, deltoctl_sim):
    buses = deltoctl_sim.buses("mh5")
    result = cli("--json", "-p", "mh5", *_mh5_targets(buses, lower_body=1_500_000), "identify")
    assert result.exit_code == 2 and result.stdout == ""
    error = json.loads(result.stderr)["error"]
    assert error["exit_code"] == 2 and RATES in error["message"]


def test_a_rate_of_the_table_is_a_target_like_any(cli, deltoctl_sim):
    """57600 is a rate the servos run, only not the one they are set to: the bus is opened
    and nothing answers there (exit 4), no usage error."""
    buses = deltoctl_sim.buses("mh5")
    result = cli("-p", "mh5", *_mh5_targets(buses, upper_body=57600), "connect")
    assert result.exit_code == 4, result.stderr
    assert "cannot run at" not in result.stderr


def test_a_profile_whose_bus_runs_at_no_servo_rate_is_refused_with_sim(cli, tmp_path):
    from tests.conftest import REPO

    text = (REPO / "profiles" / "mh5.yaml").read_text().replace("baud=2000000", "baud=123")
    profile = tmp_path / "mh5-123.yaml"
    profile.write_text(text)
    for args in (("--sim", "connect"), ("sim", "serve", str(profile))):
        result = cli("-p", str(profile), *args)
        assert result.exit_code == 2, (args, result.stderr, result.exception)
        assert "cannot run at 123 baud" in result.stderr and RATES in result.stderr


@pytest.mark.parametrize(("profile", "target"), [
    ("dg-5f-right", "tcp://[::1"),
    ("dg-5f-right", "tcp://[::1:502"),
    ("bioscara-arm", "i2c+tcp://[::1"),
    ("bioscara-arm", "i2c://[dev/i2c-1"),
])
def test_a_url_that_cannot_be_read_is_a_usage_error_naming_it(cli, profile, target):
    result = cli("-p", profile, "-t", target, "connect")
    assert result.exit_code == 2, (result.stderr, result.exception)
    assert f"{target!r} is not a valid URL" in result.stderr
    assert "internal error" not in result.stderr


def test_a_serial_url_that_cannot_be_read_is_a_usage_error(cli):
    result = cli("-p", "mh5", "-t", "upper_body=serial://[dev/ttyUSB0", "-t",
                 "lower_body=serial:///dev/null?baud=2000000", "-t", "i2c=i2c:///dev/i2c-1",
                 "connect")
    assert result.exit_code == 2, (result.stderr, result.exception)
    assert "'serial://[dev/ttyUSB0' is not a valid URL" in result.stderr


def test_a_profile_bus_that_cannot_be_read_is_a_usage_error(cli, tmp_path):
    from tests.conftest import REPO

    text = (REPO / "profiles" / "dg-5f-right.yaml").read_text()
    profile = tmp_path / "bad-url.yaml"
    profile.write_text(text.replace("gripper: tcp://169.254.186.72:502", 'gripper: "tcp://[::1"'))
    result = cli("-p", str(profile), "connect")
    assert result.exit_code == 2, (result.stderr, result.exception)
    assert "'tcp://[::1' is not a target URL" in result.stderr


# -- a serial port whose device goes away ----------------------------------------------------------

def test_a_pty_whose_master_closed_fails_with_an_oserror():
    """pyserial flushes with termios, whose error is no OSError: the port raises OSError (EIO)
    as for every other failure, which the lost-bus path takes."""
    import errno
    import os

    from deltoctl.transport.serial_port import open_serial

    master, slave = os.openpty()
    path = os.ttyname(slave)
    os.close(slave)
    port = open_serial(f"serial://{path}?baud=2000000")
    try:
        port.reset_input_buffer()  # fine while the other end is there
        os.close(master)
        for call in (port.reset_input_buffer, port.reset_output_buffer, port.flush):
            with pytest.raises(OSError) as caught:
                call()
            assert caught.value.errno == errno.EIO
    finally:
        port.close()


@pytest.mark.slow
def test_a_servo_bus_closed_mid_record_is_a_lost_bus_every_time(tmp_path):
    """The bus's pseudo-terminal closed at any moment of a record's cycle: never an internal
    error, always the lost bus (exit 4) and a readable file."""
    import os
    import subprocess
    import sys
    import time

    from mcap.reader import make_reader

    from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo
    from deltoctl.profile.catalog import load_profile
    from tests.conftest import REPO, eventually

    hw = next(h for h in load_profile("mh5").hardware if h.name == "upper_body")
    for run in range(6):
        server = DynamixelPtyServer(DynamixelBus([Servo(j.address) for j in hw.joints])).start()
        out = tmp_path / f"bus-{run}.mcap"
        proc = subprocess.Popen(
            [sys.executable, "-m", "deltoctl", "-p", "mh5", "--hardware", "upper_body", "-t",
             f"upper_body=serial://{server.port}?baud=2000000", "record", str(out),
             "--rate", "200", "--duration", "1.5"],
            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            assert eventually(lambda f=out: proc.poll() is not None  # noqa: B023
                              or (f.exists() and f.stat().st_size > 0), timeout=30)
            # the test holds the pty's other end: its number is not given to a new pty (the
            # bus would "come back" as another device) and reopening it fails, as a bus
            # whose adapter was pulled
            held = os.open(server.port, os.O_RDWR | os.O_NOCTTY)
            time.sleep(0.05 * run)  # a different moment of the cycle each run
            server.close()
            _, err = proc.communicate(timeout=60)
            os.close(held)
        finally:
            proc.kill()
            server.close()
        assert proc.returncode == 4, (run, err)
        assert "internal error" not in err and "Traceback" not in err, err
        assert "upper_body" in err and "did not come back" in err
        with out.open("rb") as f:  # whole: indexed, with the cycles before the loss
            assert make_reader(f).get_summary().statistics.message_count > 0
