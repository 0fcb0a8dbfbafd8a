"""The Zenoh configuration of an agent or a caller: a Zenoh JSON5 file (``--zenoh-config`` or
``DELTOCTL_ZENOH_CONFIG``), else safe defaults: the agent listens on loopback only, the caller
connects there; no multicast scouting either way. An agent never scouts (multicast or gossip):
it links only through the endpoints its config names, so their TLS settings say who reaches
it; a config file that names none to listen on (in peer or router mode) listens on loopback,
never on Zenoh's default of every interface. And the rule that decides whether an agent's
peers are authenticated."""

from __future__ import annotations

import json
import os
import re
from typing import Any

from deltoctl.errors import InvalidInput
from deltoctl.fleet import zenoh_module

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
ENV = "DELTOCTL_ZENOH_CONFIG"


def config_file(option: str | None) -> str | None:
    return option or os.environ.get(ENV) or None


def load(path: str | None, role: str, listen: list[str] | None = None,
         connect: list[str] | None = None) -> Any:
    """A ``zenoh.Config`` for ``role`` "agent" or "caller" from ``path`` (or the defaults),
    with ``listen``/``connect`` endpoints given on the command line replacing the file's."""
    zenoh = zenoh_module()
    if path:
        try:
            config = zenoh.Config.from_file(path)
        except Exception as exc:  # zenoh raises ZError with the parser's message
            raise InvalidInput(f"zenoh config {path}: {zenoh_message(exc)}",
                               "a Zenoh JSON5 configuration file: `deltoctl help "
                               "examples` ships some, `deltoctl help security` says why") from None
    else:
        config = zenoh.Config()
        config.insert_json5("scouting/multicast/enabled", "false")
        if role == "agent":
            config.insert_json5("mode", '"peer"')
            config.insert_json5("listen/endpoints", json.dumps([DEFAULT_ENDPOINT]))
        else:
            config.insert_json5("mode", '"client"')
            config.insert_json5("connect/endpoints", json.dumps([DEFAULT_ENDPOINT]))
    if role == "agent":  # it links only where its config says: no peer found by scouting
        config.insert_json5("scouting/multicast/enabled", "false")
        config.insert_json5("scouting/gossip/enabled", "false")
        if not listen and _listens_by_default(config):
            config.insert_json5("listen/endpoints", json.dumps([DEFAULT_ENDPOINT]))
    for given in (*(listen or []), *(connect or [])):
        if not re.fullmatch(r"[a-z0-9]+/\S+", given):
            raise InvalidInput(f"endpoint {given!r}: a Zenoh endpoint is PROTOCOL/ADDRESS:PORT, "
                               "e.g. tcp/127.0.0.1:7447 or tls/192.168.1.10:7447")
    try:
        if listen:
            config.insert_json5("listen/endpoints", json.dumps(listen))
        if connect:
            config.insert_json5("connect/endpoints", json.dumps(connect))
    except Exception as exc:
        raise InvalidInput(f"endpoints {listen or connect}: {zenoh_message(exc)}") from None
    return config


def _listens_by_default(config: Any) -> bool:
    """A peer or router whose config names no endpoint to listen on (an empty list says:
    nowhere): Zenoh's default is every interface (``tcp/[::]:0``)."""
    mode = _get(config, "mode") or "peer"
    found = _get(config, "listen/endpoints")
    default = _get(zenoh_module().Config(), "listen/endpoints")
    return mode != "client" and (found is None or found == default
                                 or (isinstance(found, dict) and mode not in found))


def _get(config: Any, path: str) -> Any:
    try:
        return json.loads(config.get_json(path))
    except Exception:
        return None


def endpoints(config: Any, which: str) -> list[str]:
    """The ``listen`` or ``connect`` endpoints of a config (a list, or one list per mode)."""
    found = _get(config, f"{which}/endpoints")
    if isinstance(found, dict):
        mode = _get(config, "mode") or "peer"
        found = found.get(mode, [])
    return [e for e in found or [] if isinstance(e, str)]


def mutual_tls(config: Any) -> bool:
    """Every link of this node is TLS with client certificates checked (mTLS): each endpoint
    it listens on or connects to is ``tls/``, and ``transport/link/tls/enable_mtls`` is on."""
    ends = endpoints(config, "listen") + endpoints(config, "connect")
    return bool(ends) and all(e.startswith("tls/") for e in ends) and \
        _get(config, "transport/link/tls/enable_mtls") is True


def loopback_only(config: Any) -> bool:
    """Every endpoint is on this computer (and the node listens somewhere explicit)."""
    ends = endpoints(config, "listen") + endpoints(config, "connect")
    return bool(ends) and all(_on_loopback(e) for e in ends)


def _on_loopback(endpoint: str) -> bool:
    """``tcp/127.0.0.1:7447``, ``tls/[::1]:7447``, ``tcp/localhost:7447`` (options after
    ``#`` or ``?`` ignored): the host, exactly, is a loopback address or ``localhost``."""
    import ipaddress

    address = re.split(r"[#?]", endpoint.split("/", 1)[-1], maxsplit=1)[0]
    host = address.rpartition(":")[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


TLS_FILES = ("root_ca_certificate", "listen_private_key", "listen_certificate",
             "connect_private_key", "connect_certificate")


def tls_files(config: Any) -> list[str]:
    """The certificate and key files the config names."""
    tls = _get(config, "transport/link/tls")
    return [tls[k] for k in TLS_FILES if isinstance(tls, dict) and isinstance(tls.get(k), str)]


def describe(config: Any) -> str:
    listen, connect = endpoints(config, "listen"), endpoints(config, "connect")
    parts = ([f"listening on {', '.join(listen)}"] if listen else []) + \
        ([f"connecting to {', '.join(connect)}"] if connect else [])
    return "; ".join(parts) or "default endpoints"


def zenoh_message(exc: BaseException) -> str:
    """Zenoh's error without the Rust source location it appends."""
    text = " ".join(re.split(r"\s+at \S+\.rs:\d+", str(exc))[0].split())
    return text.rstrip(".!") or type(exc).__name__


def open_session(config: Any, what: str, hint: str | None = None) -> Any:
    """``zenoh.open``; a failure (nothing answers, a certificate is refused) is exit 4."""
    from deltoctl.errors import Unreachable

    zenoh = zenoh_module()
    try:
        return zenoh.open(config)
    except Exception as exc:
        raise Unreachable(f"{what}: cannot open the Zenoh session ({describe(config)}): "
                          f"{zenoh_message(exc)}",
                          hint or "is an agent or a router listening there? --zenoh-config FILE"
                          f" (or {ENV}) names the endpoints and TLS settings") from None
