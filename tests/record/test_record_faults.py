"""record survives: signals to the process group, a parent killed, a full disk, a file too
large, a directory removed, a link lost for good — the file stays a readable MCAP and the exit
code says what happened."""

from __future__ import annotations

import contextlib
import errno
import io
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.records import Footer
from mcap.stream_reader import StreamReader

from deltoctl.families.delto.emulator import DeltoServer, firmware_for_profile
from deltoctl.profile.catalog import load_profile
from tests.conftest import REPO, eventually, record_with_a_dropped_link, ros2_messages

pytestmark = pytest.mark.slow  # each test records for a second or more
SIM = ("-p", "dg-5f-right", "--sim")


def check_mcap(path: Path, indexed: bool = True) -> int:
    """The file reads whole: every record (chunk CRCs checked) up to a footer and the closing
    magic, and make_reader's messages; with ``indexed``, its summary counts them too. Returns
    the number of messages."""
    with path.open("rb") as f:
        records = list(StreamReader(f, validate_crcs=True).records)
    assert isinstance(records[-1], Footer)
    with path.open("rb") as f:
        reader = make_reader(f)
        count = sum(1 for _ in reader.iter_messages())
        summary = reader.get_summary()
    if indexed:
        assert summary is not None and summary.statistics.message_count == count
    assert sum(1 for _ in ros2_messages(path)) == count  # every message decodes
    return count


def deltoctl(*args: str, **popen: object) -> subprocess.Popen:
    """deltoctl in a process group of its own, as a shell or a supervisor starts it."""
    return subprocess.Popen([sys.executable, "-m", "deltoctl", *args], cwd=REPO,
                            start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **popen)


def recording(out: Path, proc: subprocess.Popen, seconds: float = 0.5) -> None:
    """Wait until the recorder has started writing, then ``seconds`` more."""
    assert eventually(lambda: proc.poll() is not None or (out.exists() and out.stat().st_size > 0),
                      timeout=15)
    assert proc.poll() is None, proc.communicate()[1]
    time.sleep(seconds)


def finished(proc: subprocess.Popen, timeout: float = 15) -> tuple[int, str]:
    try:
        _, err = proc.communicate(timeout=timeout)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    assert "Traceback" not in err, err
    return proc.returncode, err


def children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        with contextlib.suppress(OSError, ValueError, IndexError):
            if entry.name.isdigit() and \
                    int((entry / "stat").read_text().rpartition(")")[2].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def gone(pid: int) -> bool:
    """Exited (a zombie counts: nothing may reap it in a container)."""
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rpartition(")")[2].split()[0] \
            == "Z"
    except OSError:
        return True


# -- signals ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP],
                         ids=lambda s: signal.Signals(s).name)
def test_a_signal_to_the_group_ends_the_recording_cleanly(tmp_path, sig):
    """Ctrl-C, a supervisor's SIGTERM and a closed terminal's SIGHUP reach every process of
    the group, the recorder too: it lets the loop decide, and the file ends indexed."""
    out = tmp_path / "group.mcap"
    proc = deltoctl(*SIM, "record", str(out), "--rate", "100")
    recording(out, proc)
    os.killpg(proc.pid, sig)
    code, err = finished(proc)
    assert code == 0, err
    assert check_mcap(out) > 0
    with out.open("rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert int(meta["recording"]["cycles"]) > 0  # the loop's last word reached the file


def test_the_recorder_finishes_the_file_when_its_parent_is_killed(tmp_path):
    out = tmp_path / "orphan.mcap"
    proc = deltoctl(*SIM, "record", str(out), "--rate", "100")
    recording(out, proc)
    recorder = children(proc.pid)
    assert recorder
    proc.kill()  # the parent only
    finished(proc)

    def indexed() -> bool:
        with contextlib.suppress(Exception), out.open("rb") as f:
            return make_reader(f).get_summary() is not None
        return False

    assert eventually(indexed, timeout=5)
    assert eventually(lambda: all(gone(pid) for pid in recorder), timeout=5)
    assert check_mcap(out) > 0


def test_a_file_reads_even_when_the_whole_group_is_killed(tmp_path):
    """SIGKILL cannot be ignored; the file still ends validly after every chunk written (one
    a second at least), so it reads up to the last second, unindexed."""
    out = tmp_path / "killed.mcap"
    proc = deltoctl(*SIM, "record", str(out), "--rate", "100")
    recording(out, proc, seconds=1.6)
    os.killpg(proc.pid, signal.SIGKILL)
    finished(proc)
    time.sleep(0.2)
    assert check_mcap(out, indexed=False) > 0


ORPHAN = textwrap.dedent("""
    import os, sys, time
    from pathlib import Path
    from deltoctl.profile.catalog import load_profile
    from deltoctl.record.recorder_process import RecorderProcess

    recorder = RecorderProcess(Path(sys.argv[1]), load_profile("dg-4f"), {})
    for i in range(20):
        recorder.write({"j_dg_1_1/position": i / 10}, time.time_ns())
    recorder._flush()
    holder = os.fork()
    if holder == 0:  # keeps the pipe's writing end open after its parent dies
        time.sleep(60)
        os._exit(0)
    print(holder, flush=True)
    time.sleep(60)
""")


def test_the_recorder_notices_its_parent_died_while_the_pipe_stays_open(tmp_path):
    """A process forked by the parent holds the pipe open, so no EOF comes: the recorder
    looks at its parent's pid when the pipe is idle."""
    out = tmp_path / "held.mcap"
    proc = subprocess.Popen([sys.executable, "-c", ORPHAN, str(out)], cwd=REPO,
                            stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        holder = int(proc.stdout.readline())
        proc.kill()  # the holder lives on
        proc.wait(timeout=5)

        def indexed() -> bool:
            with contextlib.suppress(Exception), out.open("rb") as f:
                return make_reader(f).get_summary() is not None
            return False

        assert eventually(indexed, timeout=5)
        assert not gone(holder)
        assert check_mcap(out) > 0
        assert sum(1 for _ in ros2_messages(out, ["/joint_states"])) == 20
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)


# -- write errors ----------------------------------------------------------------------------------

def _file_size_limit(limit: int):  # type: ignore[no-untyped-def]
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes fail with EFBIG instead
    return apply


def test_a_file_too_large_stops_the_recording_with_a_readable_file(tmp_path):
    out = tmp_path / "big.mcap"
    limit = 200_000
    proc = deltoctl(*SIM, "record", str(out), "--rate", "1000", "--duration", "30",
                    preexec_fn=_file_size_limit(limit))
    code, err = finished(proc, timeout=40)
    assert code == 1, err
    assert err.count("error:") == 1
    assert "recording stopped: cannot write" in err and "File too large" in err
    assert "the file is a valid MCAP" in err
    assert out.stat().st_size <= limit
    assert check_mcap(out, indexed=False) > 0


@pytest.fixture
def small_disk():
    """A 256 KiB tmpfs (needs root); skipped where mounting is not allowed."""
    where = Path(tempfile.mkdtemp(prefix="deltoctl-full-"))
    try:
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs",
                                  str(where)], capture_output=True).returncode == 0
    except OSError:
        mounted = False
    if not mounted:
        where.rmdir()
        pytest.skip("cannot mount a small tmpfs here (not root, or no mount permission)")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)
        with contextlib.suppress(OSError):
            where.rmdir()


def test_a_full_disk_stops_the_recording_with_a_readable_file(small_disk):
    out = small_disk / "full.mcap"
    proc = deltoctl(*SIM, "record", str(out), "--rate", "1000", "--duration", "30")
    code, err = finished(proc, timeout=40)
    assert code == 1, err
    assert "recording stopped: cannot write" in err and "No space left on device" in err
    assert "the file is a valid MCAP" in err
    assert check_mcap(out, indexed=False) > 0


@pytest.mark.parametrize("removed", ["directory", "file"])
def test_a_file_removed_while_recording_is_saved_elsewhere(tmp_path, removed):
    run = tmp_path / "run"
    run.mkdir()
    rescue = tmp_path / "tmp"
    rescue.mkdir()
    out = run / "gone.mcap"
    proc = deltoctl(*SIM, "record", str(out), "--rate", "100",
                    env={**os.environ, "TMPDIR": str(rescue)})
    recording(out, proc)
    if removed == "directory":
        shutil.rmtree(run)
        saved = rescue / "gone.mcap"
    else:
        out.unlink()
        saved = out
    code, err = finished(proc)
    assert code == 1, err
    assert f"{out} was removed while recording; what was recorded is saved in {saved}" in err
    assert check_mcap(saved) > 0


def test_a_failed_write_never_leaves_an_unreadable_file(tmp_path, monkeypatch):
    """Whatever the byte at which the disk refuses (here: a size limit that pwrite meets,
    as RLIMIT_FSIZE does), the file is a whole MCAP holding the first messages written."""
    from deltoctl.record.mcap_recorder import McapFile, McapRecorder

    real_pwrite = os.pwrite
    profile = load_profile("dg-4f")
    keys = [f"j_dg_1_{j}/position" for j in range(1, 5)]
    per_cycle = len(McapRecorder(io.BytesIO(), profile, {}).topics)  # a message per topic

    @settings(max_examples=60, deadline=None,
              suppress_health_check=[HealthCheck.function_scoped_fixture])
    @given(limit=st.integers(0, 60_000), flush_every=st.integers(1, 200))
    def check(limit: int, flush_every: int) -> None:
        def pwrite(fd: int, data: bytes, offset: int) -> int:
            room = limit - offset
            if room <= 0:
                raise OSError(errno.EFBIG, os.strerror(errno.EFBIG))
            return real_pwrite(fd, memoryview(data)[:room], offset)

        path = tmp_path / "limited.mcap"
        written, recorder, failed = 0, None, False
        monkeypatch.setattr(os, "pwrite", pwrite)
        try:
            out = McapFile(str(path))
            try:
                recorder = McapRecorder(out, profile, {"profile": {"name": "dg-4f"}})
                for i in range(600):
                    recorder.write(dict.fromkeys(keys, i / 100), 1_000_000 + i)
                    written += 1
                    if i % flush_every == 0:
                        recorder.flush()
                recorder.close({"cycles": written}, 2_000_000)
            except OSError as exc:
                assert exc.errno == errno.EFBIG
                failed = True
                if recorder is not None:
                    recorder.close({"cycles": written}, 2_000_000)  # keeps the file as it is
            out.close()
        finally:
            monkeypatch.setattr(os, "pwrite", real_pwrite)
        assert path.stat().st_size <= limit
        if not out.readable:
            assert limit < 1000  # only when the header itself did not fit
            return
        count = check_mcap(path, indexed=not failed)
        assert count <= per_cycle * written + 1
        with path.open("rb") as f:  # the first cycles, in order, none skipped
            times = [m.log_time for _, _, m in make_reader(f).iter_messages()
                     if m.log_time < 2_000_000]
        assert times == sorted(times)
        assert not times or set(times) == set(range(1_000_000, times[-1] + 1))
        assert failed or len(times) == per_cycle * written

    check()


# -- links -----------------------------------------------------------------------------------------

def test_a_link_lost_for_good_ends_the_recording_with_exit_4(tmp_path):
    out = tmp_path / "lost.mcap"
    profile = load_profile("dg-5f-right")
    server = DeltoServer(firmware_for_profile(profile)).start()

    def pull_the_plug() -> None:
        server.shutdown()
        server.server_close()
        server.drop_connections()

    proc = deltoctl("-p", "dg-5f-right", "-t", server.endpoint, "record", str(out),
                    "--rate", "50", "--duration", "3")
    try:
        recording(out, proc)
        threading.Thread(target=pull_the_plug).start()
        code, err = finished(proc)
    finally:
        with contextlib.suppress(OSError):
            pull_the_plug()
    assert code == 4, err
    assert "was lost and did not come back" in err
    assert check_mcap(out) > 0
    events = [s.message for _, m in ros2_messages(out, ["/diagnostics"]) for s in m.status
              if s.name == "deltoctl/link"]
    assert events == ["link lost"]


def test_a_link_lost_and_restored_ends_the_recording_with_exit_3(cli, tmp_path):
    out = tmp_path / "restored.mcap"
    result = record_with_a_dropped_link(cli, out)
    assert result.exit_code == 3, result.stderr
    assert "the link was lost 1 time(s) and came back" in result.stderr
    assert check_mcap(out) > 0


def test_a_servo_bus_that_disappears_ends_the_recording_with_exit_4(tmp_path):
    """The RS-485 adapter pulled mid-record: no internal error; the bus reads as lost, the
    recording goes on to its end, the file is whole, and the exit says the link is down."""
    from deltoctl.families.dynamixel.emulator import DynamixelBus, DynamixelPtyServer, Servo

    hw = next(h for h in load_profile("mh5").hardware if h.name == "upper_body")
    server = DynamixelPtyServer(DynamixelBus([Servo(j.address) for j in hw.joints])).start()
    out = tmp_path / "bus.mcap"
    proc = deltoctl("-p", "mh5", "--hardware", "upper_body", "-t",
                    f"upper_body=serial://{server.port}?baud=2000000", "record", str(out),
                    "--duration", "2")
    recording(out, proc)
    server.close()
    code, err = finished(proc)
    assert code == 4, err
    assert "upper_body" in err and "did not come back" in err
    assert check_mcap(out) > 0
