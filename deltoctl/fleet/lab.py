"""A fleet on loopback, for tests and benchmarks: a Zenoh router, agents of simulated robots
(each its own ``deltoctl agent --sim`` process), the callers' config files, and a probe that
reads a joint straight from a simulator, beside the agent, to see when it stops moving."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from deltoctl.fleet import key, zenoh_module


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def endpoint(port: int, scheme: str = "tcp") -> str:
    return f"{scheme}/127.0.0.1:{port}"


def write_config(path: Path, mode: str, connect: Sequence[str] = (), listen: Sequence[str] = (),
                 tls: dict[str, Any] | None = None) -> Path:
    """A Zenoh JSON5 config file (JSON is JSON5): no multicast scouting, explicit endpoints."""
    doc: dict[str, Any] = {"mode": mode, "scouting": {"multicast": {"enabled": False}}}
    if connect:
        doc["connect"] = {"endpoints": list(connect)}
    if listen:
        doc["listen"] = {"endpoints": list(listen)}
    if tls:
        doc["transport"] = {"link": {"tls": tls}}
    path.write_text(json.dumps(doc, indent=2))
    return path


class Router:
    """A Zenoh router in this process, listening on loopback."""

    def __init__(self, port: int | None = None, tls: dict[str, Any] | None = None) -> None:
        zenoh = zenoh_module()
        self.port = port or free_port()
        self.endpoint = endpoint(self.port, "tls" if tls else "tcp")
        config = zenoh.Config()
        config.insert_json5("mode", '"router"')
        config.insert_json5("scouting/multicast/enabled", "false")
        config.insert_json5("listen/endpoints", json.dumps([self.endpoint]))
        if tls:
            config.insert_json5("transport/link/tls", json.dumps(tls))
        self.session = zenoh.open(config)

    def close(self) -> None:
        self.session.close()


def deltoctl_command() -> list[str]:
    return [sys.executable, "-m", "deltoctl"]


# a shell script's `deltoctl agent … &`: the agent inherits SIGINT ignored (sh does that to a
# command in the background; the trap makes sure); the shell says its pid, then waits for it
IN_BACKGROUND = ['sh', '-c', 'trap "" INT; "$@" >/dev/null & echo $!; wait', 'sh']


class AgentProcess:
    """``deltoctl agent`` in a process of its own; ``wait_ready`` until it serves. Its remote
    verbs run in ``cwd`` (``--workdir``) unless ``args`` say otherwise; ``background``: started
    as a shell script starts it in the background."""

    def __init__(self, robot: str, profile: str, args: list[str], cwd: str | None = None,
                 config: Path | None = None, background: bool = False,
                 env: dict[str, str] | None = None) -> None:
        self.robot = robot
        command = [*deltoctl_command(), "-p", profile, "--sim"]
        if config is not None:
            command += ["--zenoh-config", str(config)]
        command += ["agent", "--name", robot, *args]
        if cwd is not None and "--workdir" not in args:
            command += ["--workdir", cwd]
        env = env or {k: v for k, v in os.environ.items() if not k.startswith("DELTOCTL_")}
        self.proc = subprocess.Popen([*IN_BACKGROUND, *command] if background else command,
                                     stdout=subprocess.PIPE if background else subprocess.DEVNULL,
                                     stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, env=env,
                                     cwd=cwd)
        self.pid = self.proc.pid
        if background:  # the agent's own pid: the shell's first line
            assert self.proc.stdout is not None
            self.pid = int(self.proc.stdout.readline())
        self.log: list[str] = []
        self.ready = threading.Event()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for raw in self.proc.stderr:
            line = raw.decode(errors="replace").rstrip("\n")
            self.log.append(line)
            if ": serving " in line:
                self.ready.set()
        self.ready.set()

    def wait_ready(self, timeout: float = 60.0) -> AgentProcess:
        if not self.ready.wait(timeout) or self.proc.poll() is not None:
            raise RuntimeError(f"agent {self.robot} did not start:\n" + "\n".join(self.log))
        return self

    def text(self) -> str:
        return "\n".join(self.log)

    def stop(self, timeout: float = 15.0) -> int:
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGTERM)  # the agent (not the shell that waits)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(self.pid, signal.SIGKILL)
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode


def info(session: Any, robot: str, timeout: float = 5.0) -> dict[str, Any]:
    """The agent's info document."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in session.get(key(robot, "info"), timeout=1.0):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes())
        time.sleep(0.05)
    raise RuntimeError(f"robot {robot}: no info")


def targets(links: list[str]) -> list[str]:
    """The ``BUS=URL`` targets among an agent's links."""
    return [a.split("=", 1)[1] for a in links if a.startswith("--target=")]


class JointProbe:
    """Reads one joint's position from the simulator directly (its own connection), as fast
    as it answers; ``still_since`` says when the joint stopped moving."""

    def __init__(self, profile_name: str, target: str, joint: str) -> None:
        from deltoctl import registry
        from deltoctl.core.driver import Block
        from deltoctl.profile.catalog import load_profile

        profile = load_profile(profile_name)
        hw = next(h for h in profile.hardware if any(j.name == joint for j in h.joints))
        family = registry.of_block(profile.family_of(hw), hw.plugin)
        assert family is not None
        url = target.split("=", 1)[1] if "=" in target.split("://", 1)[0] else target
        self.driver = family.driver_class()(Block(profile, hw, family, url))
        self.driver.configure()
        self.name = f"{joint}/position"
        self.samples: list[tuple[float, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            value = self.driver.read().get(self.name)
            if value is not None:
                self.samples.append((time.monotonic(), value))
            time.sleep(0.002)

    def position(self) -> float:
        while not self.samples:
            time.sleep(0.01)
        return self.samples[-1][1]

    def moving(self, within: float = 0.05) -> bool:
        """Whether the position changed over the last ``within`` seconds."""
        now = time.monotonic()
        recent = [v for t, v in self.samples if t >= now - within]
        return len(recent) >= 2 and max(recent) - min(recent) > 1e-6

    def still(self, within: float = 0.1) -> bool:
        """Whether the position stayed the same over the last ``within`` seconds, read at
        least three times in that span (a starved probe proves nothing)."""
        now = time.monotonic()
        if not self.samples or self.samples[0][0] > now - within:
            return False
        recent = [v for t, v in self.samples if t >= now - within]
        before = [v for t, v in self.samples if t < now - within][-1:]
        values = before + recent
        return len(recent) >= 3 and max(values) - min(values) <= 1e-6

    def last_change(self) -> float:
        """When the position last changed (monotonic seconds)."""
        last = self.samples[-1][1]
        after = self.samples[-1][0]
        for t, v in reversed(self.samples):
            if abs(v - last) > 1e-6:
                return after
            after = t
        return self.samples[0][0]

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        with contextlib.suppress(Exception):
            self.driver.cleanup()


def make_pki(directory: Path, names: tuple[str, ...] = ("agent", "caller")) -> dict[str, Path]:
    """A certificate authority and, for each name, a key and a certificate it signs (for
    127.0.0.1 and localhost, usable by a server and a client): ``{"ca", NAME + "_key",
    NAME + "_cert"}`` paths. Needs the ``cryptography`` package (tests, benchmarks)."""
    import datetime
    import ipaddress

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = datetime.datetime.now(datetime.timezone.utc)
    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME,
                                            f"deltoctl test CA {directory.name}")])
    ca = (x509.CertificateBuilder().subject_name(ca_name).issuer_name(ca_name)
          .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
          .not_valid_before(now - datetime.timedelta(minutes=5))
          .not_valid_after(now + datetime.timedelta(days=1))
          .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
          .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                       content_commitment=False, key_encipherment=False,
                                       data_encipherment=False, key_agreement=False,
                                       encipher_only=False, decipher_only=False), critical=True)
          .sign(ca_key, hashes.SHA256()))
    directory.mkdir(parents=True, exist_ok=True)
    paths = {"ca": directory / "ca.pem"}
    paths["ca"].write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    for name in names:
        key_ = ec.generate_private_key(ec.SECP256R1())
        cert = (x509.CertificateBuilder()
                .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
                .issuer_name(ca_name).public_key(key_.public_key())
                .serial_number(x509.random_serial_number())
                .not_valid_before(now - datetime.timedelta(minutes=5))
                .not_valid_after(now + datetime.timedelta(days=1))
                .add_extension(x509.SubjectAlternativeName([
                    x509.DNSName("localhost"),
                    x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
                .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH,
                                                      ExtendedKeyUsageOID.CLIENT_AUTH]),
                               critical=False)
                .sign(ca_key, hashes.SHA256()))
        paths[f"{name}_key"] = directory / f"{name}.key"
        paths[f"{name}_key"].write_bytes(key_.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption()))
        paths[f"{name}_key"].chmod(0o600)
        paths[f"{name}_cert"] = directory / f"{name}.pem"
        paths[f"{name}_cert"].write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return paths


def tls_settings(pki: dict[str, Path], name: str | None, mtls: bool = True) -> dict[str, Any]:
    """``transport/link/tls`` for a node holding ``name``'s certificate (None: none, only the
    CA to check the other side)."""
    tls: dict[str, Any] = {"root_ca_certificate": str(pki["ca"])}
    if name is not None:
        key_, cert = str(pki[f"{name}_key"]), str(pki[f"{name}_cert"])
        tls.update({"listen_private_key": key_, "listen_certificate": cert,
                    "connect_private_key": key_, "connect_certificate": cert})
    if mtls:
        tls["enable_mtls"] = True
    return tls
