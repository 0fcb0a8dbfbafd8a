"""The ``deltoctl sim serve`` processes running for this user, so that ``--sim`` drives one
already serving the profile (homed by the last command) instead of a fresh simulator.

Each server writes a small JSON file in a directory of the user's own (``$XDG_RUNTIME_DIR/
deltoctl/sims``, else ``/tmp/deltoctl-UID/sims``, mode 0700) and removes it on exit. A file is
untrusted: it is read only when the directory and the file are the user's and no one else may
write them, a server whose process is gone is forgotten (its file removed), and its targets
must be simulators of this computer — loopback addresses or pseudo-terminals — so that a
``--sim`` never drives hardware."""

from __future__ import annotations

import contextlib
import hashlib
import ipaddress
import json
import os
import stat
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

ENV_DIR = "XDG_RUNTIME_DIR"
MAX_BYTES = 64 * 1024  # a server's file is a few hundred bytes


class Served:
    """A running ``sim serve``: its process and the targets of the blocks asked for."""

    def __init__(self, pid: int, profile: str, targets: list[str]) -> None:
        self.pid, self.profile, self.targets = pid, profile, targets
        self.name = f"sim serve (pid {pid})"


def fresh_hint(profile: str) -> str:
    """What to do when a simulator ``--sim`` started refuses a joint that is not homed."""
    return (f"each --sim starts a fresh simulator, which no earlier command homed: run "
            f"'deltoctl sim serve {profile}' in another terminal, and --sim uses it (home once, "
            "then jog)")


def sims_dir() -> Path:
    """Where the servers of this user say what they serve."""
    base = os.environ.get(ENV_DIR)
    if base and os.path.isabs(base):
        return Path(base) / "deltoctl" / "sims"
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return Path(tempfile.gettempdir()) / f"deltoctl-{uid}" / "sims"


def profile_hash(profile: Any) -> str:
    """The profile's content, as deltoctl reads it (its YAML export), hashed."""
    from deltoctl.profile.exporter import to_yaml

    return hashlib.sha256(to_yaml(profile).encode()).hexdigest()


def normal_faults(faults: Mapping[str, Any]) -> dict[str, Any]:
    """Faults as asked, comparable: an option left off (None, False, no joints) dropped,
    joints as a list."""
    out: dict[str, Any] = {}
    for name, value in faults.items():
        if value in (None, False, (), []):
            continue
        out[name] = list(value) if isinstance(value, list | tuple) else value
    return dict(sorted(out.items()))


def is_local_simulator(url: str) -> bool:
    """Whether a target is a simulator of this computer: a loopback host, or a pseudo-terminal
    (``serial:///dev/pts/3``)."""
    try:
        parts = urlsplit(url)
        host = parts.hostname
    except ValueError:
        return False
    if not parts.scheme:
        return False
    if host is None:
        return not parts.netloc and parts.path.startswith("/dev/pts/") and ".." not in parts.path
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@contextlib.contextmanager
def registered(profile: Any, faults: Mapping[str, Any], blocks: Sequence[str],
               buses: Mapping[str, str], warn: Callable[[str], None]) -> Iterator[Path | None]:
    """Say that this process serves ``buses`` for ``blocks`` of ``profile`` with ``faults``,
    until the block ends. A directory that cannot be made private is warned about, and the
    server goes on unregistered; so does one listening beyond loopback (``--host``), which
    ``--sim`` would not trust."""
    if not all(is_local_simulator(url) for url in buses.values()):
        yield None
        return
    try:
        folder = _private_dir(create=True)
    except OSError as exc:
        warn(f"--sim will not find this simulator: {exc}")
        yield None
        return
    entry = {"pid": os.getpid(), "profile": profile.name, "hash": profile_hash(profile),
             "faults": normal_faults(faults), "blocks": list(blocks), "buses": dict(buses)}
    path = folder / f"{os.getpid()}.json"
    temp = None
    try:  # a full or read-only directory: warned about, the server goes on unregistered
        fd, temp = tempfile.mkstemp(dir=folder, prefix=".", suffix=".tmp")
        with os.fdopen(fd, "w") as f:
            json.dump(entry, f)
        os.replace(temp, path)
    except OSError as exc:
        if temp is not None:
            with contextlib.suppress(OSError):
                os.unlink(temp)
        warn(f"--sim will not find this simulator: {exc}")
        yield None
        return
    try:
        yield path
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)


def find(profile: Any, faults: Mapping[str, Any], hardware: Sequence[str],
         warn: Callable[[str], None]) -> Served | None:
    """A running server of this content of ``profile`` with these ``faults`` that serves every
    block ``hardware`` selects, with the targets of their buses; None when there is none. A
    file that cannot be trusted is warned about and skipped; one of a process that is gone is
    removed."""
    from deltoctl.core.system import select_blocks

    blocks = [hw.name for hw in select_blocks(profile, hardware)]
    try:
        folder = _private_dir(create=False)
    except FileNotFoundError:
        return None
    except OSError as exc:
        warn(f"not looking for a running 'sim serve': {exc}")
        return None
    wanted = normal_faults(faults)
    digest = ""  # the profile's hash, once a server of its name is found
    buses = {hw.bus for hw in profile.hardware if hw.name in blocks and hw.bus}
    for path in sorted(folder.glob("*.json")):
        entry = _read(path, warn)
        if entry is None or (entry["profile"], entry["faults"]) != (profile.name, wanted):
            continue
        digest = digest or profile_hash(profile)
        if entry["hash"] != digest or not set(blocks) <= set(entry["blocks"]) \
                or not buses <= set(entry["buses"]):
            continue
        targets = [f"{bus}={url}" for bus, url in entry["buses"].items() if bus in buses]
        return Served(entry["pid"], entry["profile"], targets)
    return None


def _private_dir(create: bool) -> Path:
    """The directory, made if asked (mode 0700), when it is the user's and private; else
    OSError saying why."""
    folder = sims_dir()
    if create:
        folder.parent.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        for d in (folder.parent, folder):
            d.mkdir(mode=0o700, exist_ok=True)
    for d in (folder.parent, folder):
        info = os.lstat(d)
        if not stat.S_ISDIR(info.st_mode):
            raise OSError(f"{d} is not a directory")
        if hasattr(os, "getuid") and info.st_uid != os.getuid():
            raise OSError(f"{d} belongs to another user")
        if info.st_mode & 0o077:
            raise OSError(f"{d} is open to other users (mode {stat.S_IMODE(info.st_mode):o}, "
                          "0700 expected)")
    return folder


def _read(path: Path, warn: Callable[[str], None]) -> dict[str, Any] | None:
    """A server's entry, checked; None (with a warning for a bad one) when it is not usable.
    The file of a process that is gone is removed."""
    try:
        info = os.lstat(path)
        if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_BYTES:
            raise ValueError("not a small regular file")
        if hasattr(os, "getuid") and info.st_uid != os.getuid():
            raise ValueError("it belongs to another user")
        if info.st_mode & 0o022:
            raise ValueError("others may write it")
        entry = _checked(json.loads(path.read_text()))
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        warn(f"ignored {path}: {exc}")
        return None
    if not _alive(entry["pid"]):
        with contextlib.suppress(OSError):
            path.unlink()
        return None
    remote = [url for url in entry["buses"].values() if not is_local_simulator(url)]
    if remote:
        warn(f"ignored {path}: its target {remote[0]!r} is not a simulator of this computer "
             "(a loopback address or a pseudo-terminal)")
        return None
    return entry


def _checked(entry: Any) -> dict[str, Any]:
    """The entry's fields, each of its type, or ValueError."""
    kinds = {"pid": int, "profile": str, "hash": str, "faults": dict, "blocks": list,
             "buses": dict}
    if not isinstance(entry, dict) or any(not isinstance(entry.get(k), t)
                                          for k, t in kinds.items()):
        raise ValueError("not a sim serve entry")
    if isinstance(entry["pid"], bool) or entry["pid"] <= 0:
        raise ValueError("bad pid")
    if not all(isinstance(b, str) for b in entry["blocks"]) or not all(
            isinstance(k, str) and isinstance(v, str) for k, v in entry["buses"].items()):
        raise ValueError("not a sim serve entry")
    return entry


def _alive(pid: int) -> bool:
    """Whether the process runs and is a deltoctl (a pid reused by another program is not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return False  # another user's process now holds the pid
    except OSError:
        return False
    cmdline = Path(f"/proc/{pid}/cmdline")
    if cmdline.parent.parent.is_dir() and Path("/proc/self").exists():
        try:
            return b"deltoctl" in cmdline.read_bytes()
        except OSError:
            return False
    return True
