"""The fleet from the caller's side: the robots found, the command line a robot's agent runs,
and a fleet run: one verb (or a bring-up script's verbs) on many robots at once, each robot's
command lines one after the other, the fleet's outcome the worst of its robots'."""

from __future__ import annotations

import contextlib
import fnmatch
import json
import threading
import time
from collections.abc import Callable, Collection
from typing import Any

from deltoctl.errors import DeltoctlError, InvalidInput, Unreachable
from deltoctl.fleet import ACTUATING
from deltoctl.verbs import Command

# exit codes from best to worst: the fleet's code is the worst of its robots'
SEVERITY = (0, 3, 1, 4, 2, 5, 130)
MAX_SCRIPT = 1 << 20  # bytes of a bring-up script read
SHELL_ENDS = ("|", "||", "&&", ";", ">", ">>", "&")


def worst(codes: list[int]) -> int:
    rank = {c: i for i, c in enumerate(SEVERITY)}
    return max(codes, key=lambda c: rank.get(c, len(SEVERITY)), default=0)


def verb_of(argv: list[str], robot: str = "") -> Command:
    """The verb a remote command line runs (``jog``, ``gpio set``) with the options it gives,
    checked as the agent checks it; a refusal names the robot."""
    from deltoctl.fleet.argv import check_argv

    try:
        return check_argv(argv)
    except InvalidInput as exc:
        raise InvalidInput(f"robot {robot}: {exc.message}", exc.hint) from None


def strip_remote(argv: list[str]) -> list[str]:
    """The command line without ``--robot R`` and ``--zenoh-config FILE``: what the robot's
    agent runs."""
    out: list[str] = []
    skip = False
    for arg in argv:
        if skip:
            skip = False
        elif arg in ("--robot", "--zenoh-config"):
            skip = True
        elif not arg.startswith(("--robot=", "--zenoh-config=")):
            out.append(arg)
    return out


def verb_args(argv: list[str]) -> list[str]:
    """The arguments after the verb (global options come first, hoisted)."""
    from deltoctl.cmdline import needs_value

    i = 0
    while i < len(argv) and argv[i].startswith("-"):
        i += 2 if needs_value(argv[i]) else 1
    return argv[i + 1:]


def record_file_dropped(argv: list[str], value_options: Callable[[], set[str]]) -> list[str]:
    """The command line as the agent judges it: a remote record's FILE is written on this
    computer and never sent, so the agent's path rule (files in its directory only) does not
    judge it. Any other command line as it is. ``value_options``: record's options that take
    a value (where its FILE argument stands depends on them)."""
    from deltoctl import verbs
    from deltoctl.cmdline import first_argument, hoist_global_options

    hoisted = hoist_global_options(argv)
    args = verb_args(hoisted)
    try:
        if verbs.resolve(hoisted) != "record" or {"--help", "-h"} & set(args):
            return argv
    except InvalidInput:
        return argv
    at = first_argument(args, value_options())
    if at is None:
        return argv
    return hoisted[:len(hoisted) - len(args)] + args[:at] + args[at + 1:]


def command_lines(command: list[str],
                  verbs: Collection[str]) -> tuple[list[list[str]], list[str], bool]:
    """What a fleet run sends each robot: the deltoctl lines of a bring-up script when
    ``command`` is only a file's name, none of ``verbs``, with the script's lines skipped;
    else one verb's command line, its global options hoisted; and whether it is one verb."""
    import os

    from deltoctl.cmdline import hoist_global_options

    if not (command[0] not in verbs and os.path.isfile(command[0]) and len(command) == 1):
        return [hoist_global_options(list(command))], [], True
    lines, skipped = script_lines(command[0])
    return lines, skipped, False


def robots_found(session: Any, wait: float) -> list[dict[str, Any]]:
    """The robots whose agents answer within ``wait`` seconds, by name: each one's profile and
    what its agent says of it (identity, state, motion; its state "unknown" without answer)."""
    from deltoctl.fleet.remote_call import agents, infos

    found = agents(session, wait=wait)
    details = infos(session, wait=wait) if found else {}
    return [{"robot": name, "profile": profile, **{
        k: v for k, v in details.get(name, {"state": "unknown"}).items() if k != "robot"}}
        for name, profile in sorted(found.items())]


def confirmed(lines: list[list[str]], ask: Callable[[], bool]) -> list[list[str]]:
    """The command lines, each that actuates or moves with --yes once ``ask`` confirmed
    (asked once for the fleet, only when a line actuates or moves)."""
    if any(verb_of(ln) in ACTUATING for ln in lines) and ask():
        return [["--yes", *ln] if verb_of(ln) in ACTUATING else ln for ln in lines]
    return lines


def choose(found: dict[str, str], pattern: str) -> dict[str, str]:
    """The robots (name → profile) whose names match ``pattern``; none is Unreachable."""
    chosen = {r: p for r, p in found.items() if fnmatch.fnmatchcase(r, pattern)}
    if not chosen:
        raise Unreachable(f"no robot matches {pattern!r}"
                          + (f" (found: {', '.join(sorted(found))})" if found else
                             ": no agent answers on this Zenoh network"))
    return chosen


class Job:
    """One robot's part of a fleet run: its command lines, run one after the other."""

    def __init__(self, robot: str, profile: str, lines: list[list[str]]) -> None:
        self.robot, self.profile, self.lines = robot, profile, lines
        self.state = "waiting"
        self.done = 0
        self.codes: list[int] = []
        self.out: list[bytes] = []
        self.err: list[bytes] = []
        self.started = self.ended = 0.0
        self.call: Any = None

    @property
    def code(self) -> int:
        return worst(self.codes)

    def last_error(self) -> str:
        """The verb's error message (text or --json), else its last line on stderr."""
        lines = b"".join(self.err).decode(errors="replace").strip().splitlines()
        for line in reversed(lines):
            if line.startswith("deltoctl: error: "):
                return line.removeprefix("deltoctl: error: ")
            if line.startswith('{"error"'):
                with contextlib.suppress(ValueError, KeyError, TypeError):
                    return str(json.loads(line)["error"]["message"])
        return lines[-1] if lines else ""

    def run(self, session: Any) -> None:
        from deltoctl.fleet.remote_call import RemoteCall

        self.started = time.monotonic()
        for argv in self.lines:
            self.state = " ".join(a for a in argv if not a.startswith("--"))[:40]
            self.out, self.err = [], []
            try:
                self.call = RemoteCall(session, self.robot, argv, self.out.append,
                                       self.err.append)
                code = self.call.run()
            except DeltoctlError as exc:
                self.err.append(f"deltoctl: error: {exc.message}\n".encode())
                code = exc.exit_code
            except Exception as exc:  # a broken session: this robot's part only
                self.err.append(f"deltoctl: error: {exc}\n".encode())
                code = 1
            self.codes.append(code)
            self.done += 1
            if code not in (0, 3):
                break
        self.ended = time.monotonic()
        self.state = "ok" if self.code == 0 else f"exit {self.code}"

    def seconds(self) -> float:
        return (self.ended or time.monotonic()) - self.started if self.started else 0.0

    def report(self) -> dict[str, Any]:
        text = b"".join(self.out).decode(errors="replace")
        try:
            output: Any = json.loads(text) if text.strip() else None
        except ValueError:
            output = text
        return {"robot": self.robot, "profile": self.profile, "exit_code": self.code,
                "seconds": round(self.seconds(), 3), "lines_run": self.done,
                "lines": len(self.lines), "output": output,
                "error": self.last_error() if self.code not in (0, 3) else None}


def start(session: Any, chosen: dict[str, str],
          lines: list[list[str]]) -> tuple[list[Job], list[threading.Thread]]:
    """Each chosen robot's job, started in a thread of its own."""
    jobs = [Job(r, chosen[r], lines) for r in sorted(chosen)]
    threads = [threading.Thread(target=j.run, args=(session,), daemon=True) for j in jobs]
    for t in threads:
        t.start()
    return jobs, threads


def wait_for(jobs: list[Job], threads: list[threading.Thread],
             tick: Callable[[], None] | None = None) -> None:
    """Wait for every robot's job, ``tick`` called as it goes (ten times a second or so: a
    live view); Ctrl-C (KeyboardInterrupt) interrupts every robot's verb, and the wait goes on
    until each has ended."""
    while any(t.is_alive() for t in threads):
        try:
            for t in threads:
                t.join(0.1)
                if tick is not None:
                    tick()
        except KeyboardInterrupt:
            for j in jobs:
                if j.call is not None:
                    j.call.cancel()


def _script_line(words: list[str], where: str, skipped: list[str]) -> list[str] | None:
    """One shell line's deltoctl command line, or None (the reason in ``skipped``)."""
    from deltoctl.cmdline import hoist_global_options

    if not words or words[0] not in ("deltoctl", "$deltoctl", "${deltoctl}"):
        if words and "=" not in words[0]:
            skipped.append(f"{where}: not a deltoctl command line")
        return None
    ends = [i for i, w in enumerate(words) if w in SHELL_ENDS]
    if ends and words[ends[0]] in ("||", "&&", ";", "&"):
        skipped.append(f"{where}: what follows '{words[ends[0]]}' (one deltoctl command a "
                       "line runs remotely)")
    argv = hoist_global_options(words[1:ends[0] if ends else len(words)])
    if any("$" in w for w in argv):
        skipped.append(f"{where}: uses shell variables")
        return None
    try:
        verb_of(argv)
    except InvalidInput as exc:
        skipped.append(f"{where}: {exc.message.removeprefix('robot : ')}")
        return None
    return argv


def script_lines(path: str) -> tuple[list[list[str]], list[str]]:
    """The deltoctl command lines of a bring-up script (``deltoctl VERB …`` or
    ``"$deltoctl" VERB …``; a pipe or redirection ends one), and the lines skipped: shell
    lines, verbs that do not run remotely, arguments with shell variables."""
    import shlex

    try:
        with open(path, encoding="utf-8") as f:
            text = f.read(MAX_SCRIPT)
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidInput(f"{path}: cannot read the script: {exc}") from None
    lines: list[list[str]] = []
    skipped: list[str] = []
    for n, line in enumerate(text.splitlines(), start=1):
        lexer = shlex.shlex(line, posix=True, punctuation_chars=True)
        lexer.whitespace_split, lexer.commenters = True, "#"
        try:
            words = list(lexer)
        except ValueError as exc:
            skipped.append(f"{path}:{n}: {exc}")
            continue
        argv = _script_line(words, f"{path}:{n}", skipped)
        if argv is not None:
            lines.append(argv)
    if not lines:
        raise InvalidInput(f"{path}: no deltoctl command line to run remotely",
                           "a line of the script is: deltoctl VERB [ARGS]")
    return lines, skipped
