"""The fleet agent's request path, end to end on loopback: a `deltoctl agent --sim` process
open to unauthenticated peers (plain TCP), reached by real run requests — well formed
(RemoteCall) and malformed (raw Zenoh queries)."""

from __future__ import annotations

import json
import secrets
import threading

import pytest

pytest.importorskip("zenoh")

from deltoctl.fleet import EXIT, MAX_VERBS, key, lab, zenoh_module
from deltoctl.fleet.argv import MAX_ARG, MAX_ARGS, REQUEST
from deltoctl.fleet.remote_call import RemoteCall
from tests.conftest import eventually
from tests.fleet.test_fleet import Bench

ROBOT = "hand-q"


@pytest.fixture(scope="module")
def agent(tmp_path_factory):
    b = Bench(tmp_path_factory.mktemp("requests"), ROBOT, "dg-5f-right")  # no mTLS
    yield b
    b.close()


def call(agent, argv: list[str]) -> tuple[int, str, str]:
    """A well-formed run request: (exit code, stdout, stderr)."""
    out: list[bytes] = []
    err: list[bytes] = []
    code = RemoteCall(agent.session, ROBOT, argv, out.append, err.append).run()
    return code, b"".join(out).decode(), b"".join(err).decode()


def raw(agent, payload: bytes) -> list[bytes]:
    """The replies to a run query with this payload, as they come (tag byte first)."""
    zenoh = zenoh_module()
    replies = agent.session.get(key(ROBOT, "run"), payload=payload, timeout=20,
                                consolidation=zenoh.ConsolidationMode.NONE)
    return [r.ok.payload.to_bytes() if r.ok is not None else b"!" + r.err.payload.to_bytes()
            for r in replies]


def request(argv: object, **extra: object) -> bytes:
    doc = {"id": secrets.token_hex(8), "argv": argv, "key": secrets.token_hex(16), **extra}
    return json.dumps(doc).encode()


def output_2(agent) -> float:
    return json.loads(agent.local("gpio", "get", "--json").stdout)["result"]["gpio/output_2"]


# -- what a command line does is what the CLI will run -----------------------------------------

@pytest.mark.parametrize("argv, verb", [
    (["-y", "gpio", "--", "set", "output_2", "on"], "gpio set"),
    (["gpio", "--", "set", "output_2", "on", "--yes"], "gpio set"),
    (["-y", "--", "gpio", "set", "output_2", "on"], "gpio set"),
    (["gpio", "--hardware", "DG5FRightHardware", "--", "set", "output_2", "on", "-y"],
     "gpio set"),
    (["-y", "register", "--", "set", "rj_dg_1_1", "return_delay_time", "0"], "register set"),
    (["-y", "config", "--", "restore", "snapshot.yaml"], "config restore"),
    (["calibrate", "--", "ft", "--yes"], "calibrate ft"),
])
def test_double_dash_shapes_are_refused_without_mtls_and_switch_nothing(agent, argv, verb):
    code, _, err = call(agent, argv)
    assert code == 5, err
    assert f"'{verb}' refused" in err and "authenticated" in err
    assert output_2(agent) == 0.0


def test_a_refusal_names_the_rehearsal_flag_and_mutual_tls(agent):
    code, _, err = call(agent, ["gpio", "set", "output_2", "on", "--yes"])
    assert code == 5 and "--allow-unauthenticated-motion" in err
    assert "loopback" in err and "mutual TLS" in err and "zenoh-agent.json5" in err


def test_reading_verbs_still_run_for_an_unauthenticated_peer(agent):
    code, out, _ = call(agent, ["--json", "gpio", "--", "get"])
    assert code == 0 and "gpio/output_2" in json.loads(out)["result"]


def test_a_report_reads_for_an_unauthenticated_peer_and_moves_only_with_yes(agent):
    """What a command line does is its parse: `report` only reads (it runs: no tare, no
    self-test, no motion), `report --yes` and `-y report` would tare, self-test and move the
    joints (refused without mTLS)."""
    code, out, err = call(agent, ["report", "--json", "-o", "acceptance.html"])
    doc = json.loads(out)["result"]
    assert doc["kind"] == "deltoctl_report" and "refused" not in err
    # it ran: 0 or 3, or 1 when a loaded machine misses one of the profile's link timings
    assert code in (0, 3) or (code == 1 and all(f.startswith("link.") for f in doc["failed"]))
    skipped = {c["id"] for c in doc["checks"] if c["verdict"] == "skip"}
    assert {"motion", "sensors.actuated"} <= skipped
    for argv in (["report", "--yes"], ["-y", "report"], ["report", "-qy", "--json"]):
        code, _, err = call(agent, argv)
        assert code == 5, err
        assert "'report' refused" in err and "authenticated" in err


@pytest.mark.parametrize("argv", [["--install-completion"], ["--show-completion", "bash"],
                                  ["identify", "--install-completion=bash"],
                                  ["doctor", "--write-udev-rule"]])
def test_options_that_write_outside_the_workdir_are_refused(agent, argv):
    code, _, err = call(agent, argv)
    assert code == 2 and "writes outside the agent's directory" in err


# -- malformed requests: one error reply each, exit 2, no traceback --------------------------------

def _too_long_with_links() -> list[str]:
    """A command line of reading verbs that fits in a request but not, with the agent's
    links, in the message to its zygote."""
    argv = ["identify"]
    while len(json.dumps(argv)) < REQUEST - 150:
        argv += ["-q", "x" * 1000]
    return argv


MALFORMED = {
    "not JSON": b"this is not JSON",
    "not UTF-8": b"\xff\xfe{",
    "not an object": b"[1, 2, 3]",
    "nested 100,000 deep": b"[" * 100_000 + b"]" * 100_000,
    "nested within the size bound": (b'{"id": "ab", "argv": ' + b"[" * 30_000
                                     + b"]" * 30_000 + b"}"),
    "no id": json.dumps({"argv": ["identify"]}).encode(),
    "an id that is a number": request(["identify"], id=12),
    "a NUL byte": request(["gpio", "get", "output\x002"]),
    "a number in argv": request(["identify", 5]),
    "argv a string": request("identify"),
    "an empty argv": request([]),
    "a lone surrogate": request(["identify", "\ud800"]),
    "too many arguments": request(["identify", *["-q"] * (MAX_ARGS + 1)]),
    "an argument too long": request(["profile", "show", "x" * (MAX_ARG + 1)]),
    "a 112 KB command line": request(["identify", *["-q"] * 28_000]),
    "too long with the agent's links": request(_too_long_with_links()),
}


@pytest.mark.parametrize("payload", MALFORMED.values(), ids=MALFORMED.keys())
def test_a_malformed_request_gets_one_error_reply_with_exit_2(agent, payload):
    replies = raw(agent, payload)
    assert [r[:1] for r in replies] == [b"e", EXIT], replies
    assert replies[-1] == EXIT + b"2"
    assert replies[0].startswith(b"edeltoctl: error: ")
    assert "Traceback" not in agent.agent.text()


def test_after_malformed_and_oversized_requests_each_verb_is_its_own(agent):
    for payload in MALFORMED.values():
        raw(agent, payload)
    code, out, _ = call(agent, ["gpio", "get", "--json"])
    assert code == 0 and "gpio/output_2" in json.loads(out)["result"]
    code, out, _ = call(agent, ["identify", "--json"])
    assert code == 0 and "blocks" in json.loads(out)
    assert "Traceback" not in agent.agent.text()


# -- concurrency ---------------------------------------------------------------------------

def test_at_most_max_verbs_run_at_once_and_more_are_refused(agent):
    calls = [RemoteCall(agent.session, ROBOT, ["stream", "--rate", "5", "--duration", "120",
                                               "--json"], lambda _: None, lambda _: None)
             for _ in range(MAX_VERBS)]
    codes: list[int] = []
    threads = [threading.Thread(target=lambda c=c: codes.append(c.run()), daemon=True)
               for c in calls]
    for t in threads:
        t.start()
    try:
        assert eventually(lambda: len(lab.info(agent.session, ROBOT)["running"]) == MAX_VERBS,
                          timeout=60)
        code, _, err = call(agent, ["identify"])
        assert code == 5 and f"at most {MAX_VERBS} at once" in err
    finally:
        for c in calls:
            c.cancel()
        for t in threads:
            t.join(30)
    assert len(codes) == MAX_VERBS and set(codes) <= {0, 130}  # a stream ends on Ctrl-C
    assert eventually(lambda: not lab.info(agent.session, ROBOT)["running"], timeout=20)
    assert call(agent, ["identify"])[0] == 0
