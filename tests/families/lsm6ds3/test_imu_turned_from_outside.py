"""The simulated LSM6DS3 turned from outside, as a technician or a script does it: `sim serve`
in a process of its own with a face sequence (--faces) and injected bias and scale errors,
control lines on its standard input (face, tilt, rate, faces), and --sim-option for --sim; the
verbs reach the chip through the real I2C transport (i2c+tcp, loopback)."""

from __future__ import annotations

import json
import math
import queue
import subprocess
import sys
import threading
from pathlib import Path

import pytest

G = 9.80665
BIAS, SCALE, GYRO_BIAS = (0.05, -0.04, 0.06), (1.01, 0.99, 1.01), (0.004, -0.003, 0.002)
ERRORS = ["--accel-bias", "0.05,-0.04,0.06", "--accel-scale", "1.01,0.99,1.01",
          "--gyro-bias", "0.004,-0.003,0.002"]
TUMBLE = ("+z", "-z", "+x", "-x", "+y", "-y")  # the order calibrate imu --tumble asks for
WAIT = 60.0  # seconds a line may take under load


class Lines:
    """A pipe's lines, read by a thread, taken with a timeout."""

    def __init__(self, pipe) -> None:
        self.lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, args=(pipe,), daemon=True).start()

    def _read(self, pipe) -> None:
        for line in pipe:
            self.lines.put(line.rstrip("\n"))
        self.lines.put("")  # the end

    def next(self) -> str:
        line = self.lines.get(timeout=WAIT)
        assert line, "the process ended"
        return line


class Served:
    """`deltoctl sim serve mh5 --hardware i2c --json` with these options; ``send`` writes a
    control line and returns its reply (JSON)."""

    def __init__(self, *options: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "deltoctl", "--hardware", "i2c", "--json", "sim", "serve",
             "mh5", *options], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True)
        self.out, self.err = Lines(self.proc.stdout), Lines(self.proc.stderr)
        info = json.loads(self.out.next())
        self.url = info["buses"]["i2c"]
        self.controls = info["controls"]

    def send(self, line: str) -> dict:
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        return json.loads(self.out.next())

    def error(self) -> str:
        return json.loads(self.err.next())["error"]["message"]

    def close(self) -> None:
        self.proc.terminate()
        assert self.proc.wait(timeout=WAIT) == 0


@pytest.fixture
def serve():
    started: list[Served] = []

    def start(*options: str) -> Served:
        started.append(Served(*options))
        return started[-1]

    yield start
    for served in started:
        served.close()


def deltoctl(url: str, *args: str, cwd: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "deltoctl", "-p", "mh5", "--hardware", "i2c",
                             "-t", f"i2c={url}", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True, cwd=cwd)


def stream(cli, url: str, pattern: str) -> dict[str, float]:
    result = cli("-p", "mh5", "--hardware", "i2c", "-t", f"i2c={url}", "stream", "-d", "0.2",
                 "--json", "-i", pattern)
    assert result.exit_code == 0, result.stderr
    return json.loads(result.stdout.splitlines()[-1])["values"]


def recovers_the_injected_errors(calibration: dict) -> None:
    assert calibration["kind"] == "imu_calibration" and calibration["pass"] is True
    assert calibration["accel_bias"] == pytest.approx(BIAS, abs=0.03)
    assert calibration["accel_scale"] == pytest.approx(SCALE, abs=0.005)
    assert calibration["gyro_bias"] == pytest.approx(GYRO_BIAS, abs=0.002)


def test_the_tumble_completes_on_a_face_sequence_and_finds_the_injected_errors(serve, tmp_path):
    served = serve("--faces", "+z:6,-z:1.5,+x:1.5,-x:1.5,+y:1.5,-y:1.5", *ERRORS)
    verb = deltoctl(served.url, "calibrate", "imu", "--tumble", "--yes", "--json", "-n", "20",
                    "-o", str(tmp_path), cwd=tmp_path)
    out, err = verb.communicate(timeout=300)
    (block,) = json.loads(out)["blocks"]
    verdicts = {c["id"]: c["verdict"] for c in block["checks"]}
    tumble = {k: v for k, v in verdicts.items() if k.split(".")[1].startswith(("accel_",
                                                                              "gyro_"))}
    assert len(tumble) == 9 and set(tumble.values()) == {"pass"}, verdicts
    # the chip turns on its own clock: a check before the tumble may catch it turning
    turned = {k for k, v in verdicts.items() if v == "fail"}
    assert turned <= {k for k in verdicts if ".self_test." in k or k.endswith(".at_rest")}
    assert verb.returncode == (1 if turned else 0), err
    assert [line.split(" face")[0] for line in err.splitlines() if "face down" in line] == [
        f"put the IMU's {'-' if a[0] == '+' else '+'}{a[1].upper()}" for a in TUMBLE]
    (path,) = tmp_path.glob("calibration-LSM6DS3TR-C-0x6a-*.json")
    assert block["calibration_file"] == str(path)
    recovers_the_injected_errors(json.loads(path.read_text()))


def test_a_script_answers_each_prompt_with_a_control_line(serve, tmp_path):
    """A technician's rehearsal in two terminals: the verb says which face to put down, the
    control line `face AXIS` on the simulator's standard input turns the chip."""
    served = serve(*ERRORS)
    assert served.controls == ["face", "faces", "rate", "tilt"]
    verb = deltoctl(served.url, "calibrate", "imu", "--tumble", "--yes", "-n", "20",
                    "-o", str(tmp_path), cwd=tmp_path)
    prompts = Lines(verb.stderr)
    for axis in TUMBLE:
        line = prompts.next()
        while "face down" not in line:
            line = prompts.next()
        assert f"({axis[0]}{axis[1].upper()} axis up)" in line
        assert served.send(f"face {axis}") == {"control": f"face {axis}",
                                               "reply": f"imu: {axis} up"}
    verb.wait(timeout=WAIT)
    assert verb.returncode == 0, verb.stdout.read()
    (path,) = tmp_path.glob("calibration-LSM6DS3TR-C-0x6a-*.json")
    recovers_the_injected_errors(json.loads(path.read_text()))


def test_control_lines_change_what_a_read_sees(serve, cli):
    served = serve("--gyro-scale", "1,1,1.1", "--gyro-bias", "0,0,0.01")
    assert stream(cli, served.url, "imu/linear*")["imu/linear_acceleration.z"] == \
        pytest.approx(G, abs=0.1)
    assert served.send("face -x")["reply"] == "imu: -x up"
    values = stream(cli, served.url, "imu/linear*")
    assert values["imu/linear_acceleration.x"] == pytest.approx(-G, abs=0.1)
    assert values["imu/linear_acceleration.z"] == pytest.approx(0.0, abs=0.1)
    served.send("tilt 30 0")
    values = stream(cli, served.url, "imu/linear*")
    assert values["imu/linear_acceleration.y"] == pytest.approx(G * math.sin(math.radians(30)),
                                                                abs=0.1)
    # the gyroscope reads its injected scale and bias on a turn
    served.send("rate 0 0 90")
    rate = stream(cli, served.url, "imu/angular*")["imu/angular_velocity.z"]
    assert rate == pytest.approx(1.1 * math.radians(90) + 0.01, abs=0.02)
    # a bad line is one error on stderr, and the simulator goes on serving
    served.proc.stdin.write("face up\nspin 1\ntilt 1e9 0\n")
    served.proc.stdin.flush()
    assert served.error() == "face up: takes one axis to put up (+z, -z, +y, -y, +x, -x), " \
                             "got 'up'"
    assert "unknown control 'spin'" in served.error()
    assert "each within ±360" in served.error()
    assert [line.split()[0] for line in served.send("help")["reply"].splitlines()] == [
        "face", "faces", "rate", "tilt", "help:"]
    served.send("faces +y:600")
    assert stream(cli, served.url, "imu/linear*")["imu/linear_acceleration.y"] == \
        pytest.approx(G, abs=0.1)


def test_sim_option_gives_sim_the_face_sequence_and_errors(cli):
    result = cli("-p", "mh5", "--hardware", "i2c", "--sim", "--sim-option", "faces=-y:600",
                 "--sim-option", "accel-bias=0,0.2,0", "stream", "-d", "0.2", "--json", "-i",
                 "imu/linear*")
    assert result.exit_code == 0, result.stderr
    values = json.loads(result.stdout.splitlines()[-1])["values"]
    assert values["imu/linear_acceleration.y"] == pytest.approx(-G + 0.2, abs=0.1)


@pytest.mark.parametrize("args, message", [
    (["sim", "serve", "mh5", "--faces", "+z:2,+w:2"], "--faces takes"),
    (["sim", "serve", "mh5", "--faces", "+z:0.1"], "each 0.5 to 600 s"),
    (["sim", "serve", "mh5", "--faces", "+z:nan"], "--faces takes"),
    (["sim", "serve", "mh5", "--faces", ",".join(["+z:1"] * 37)], "1 to 36 of them"),
    (["sim", "serve", "mh5", "--accel-bias", "9,0,0"], "each -5 to 5"),
    (["sim", "serve", "mh5", "--gyro-scale", "1,1"], "3 of them"),
    (["sim", "serve", "mh5", "--accel-scale", "1,1,inf"], "--accel-scale takes"),
    (["-p", "mh5", "--sim-option", "faces=+z:2", "stream"], "add --sim"),
    (["-p", "mh5", "--sim", "--sim-option", "faces", "stream"], "not of the form NAME=VALUE"),
    (["-p", "mh5", "--sim", "--sim-option", "faces=+z:1", "--sim-option", "faces=-z:1",
      "stream"], "faces is given twice"),
    (["-p", "dg-4f", "--sim", "--sim-option", "faces=+z:1", "identify"], "not for dg-4f"),
])
def test_a_bad_option_is_one_clear_error(cli, args, message):
    result = cli(*args)
    assert result.exit_code == 2, result.stderr
    assert message in result.stderr and "Traceback" not in result.stderr


def test_the_pytest_fixture_runs_control_lines_too(deltoctl_sim, cli):
    from deltoctl.errors import InvalidInput

    url = deltoctl_sim.buses("mh5", accel_scale=(1.0, 1.0, 1.02))["i2c"]
    assert deltoctl_sim.control("face -z") == "imu: -z up"
    assert stream(cli, url, "imu/linear*")["imu/linear_acceleration.z"] == \
        pytest.approx(-1.02 * G, abs=0.1)
    with pytest.raises(InvalidInput, match="faces takes"):
        deltoctl_sim.control("faces +z:1000")
