"""What every verb's help shows besides its own options: the global options in their panel,
the verb's effect on the robot, its example (from deltoctl.verbs) and the exit codes. The CLI
applies it to its click commands only when help is shown or a command line is completed: a
verb that just runs pays nothing for it. The longer help texts of verbs and options are here
too (DESCRIPTIONS, OPTION_HELP): each verb's module declares its command with its own."""

from __future__ import annotations

from typing import Any

from deltoctl import verbs

EXIT_LINE = ("Exit codes: 0 ok · 1 failed · 2 usage or invalid input · 3 warnings · "
             "4 unreachable · 5 refused for safety · 130 interrupted")
# one example per verb, shown in its help (command path without "deltoctl")
EXAMPLES = verbs.examples()
GLOBAL_PANEL = "Global options (before or after the verb)"
_NOT_GLOBAL = ("version", "help", "install_completion", "show_completion")

# the help of the verbs whose description runs past two lines, by command path (each other
# verb's is its function's docstring); typer dedents it as it dedents a docstring
DESCRIPTIONS = {
    "agent": """\
    Serve the robot of --profile (its links from --target, or --sim) over Zenoh until
    Ctrl-C or SIGTERM: every verb as a queryable, a liveliness token, a deadman on motion.

    Motion and outputs are served only to authenticated callers: when every link of the
    agent is mutual TLS (`deltoctl help security`).""",
    "bench loop": """\
    The read+write cycle of N hands while recording, paced and unpaced.

    A gripper profile (default dg-5f-right: F/T and IO), N copies of its block, each against
    its own `sim serve` over loopback TCP, through the cycle runner, recording to MCAP; beside
    it, the same loop idle (what this machine allows). With --foxglove, the paced run again
    while the live view serves it to a Foxglove WebSocket client in another process.""",
    "bench dynamixel": """\
    Dynamixel sync reads against dynamixel-sdk, and against the wire's limit.

    Present load/velocity/position (126, 10) from N servos of an emulated bus in another
    process: deltoctl's driver against dynamixel-sdk's GroupSyncRead; then, with the bus paced
    at 1 and 2 Mbps, deltoctl's rate against the wire's limit.""",
    "bench feetech": """\
    Feetech sync reads side by side with scservo_sdk, and against the wire's limit.

    Present position/velocity/load (56, 6) of N STS3215 (an SO-101 arm's bus) on an emulated
    bus in another process: deltoctl's driver and scservo_sdk's GroupSyncRead paced at 1 Mbps
    against the wire's limit, then unpaced, with the CPU each spends a read.""",
    "bench i2c": """The Bioscara read cycle against the I2C wire time.

    Position and velocity of bioscara-arm's four joints, each reply with its flags, on the
    in-process emulator: deltoctl's own time per transaction, without the emulator's, against
    the I2C wire time; beside it, the same transactions written straight against smbus2.""",
    "config restore": """\
    Write back what differs from a snapshot, in the order each device requires, after
    confirmation (--yes skips it); each item is verified by reading it back. A value outside
    its item's documented range is exit 2, before anything is written. Exit 1 when a
    verification fails, 5 when refused for safety (EEPROM with torque on, a safety setting
    not named by --allow), 3 when some items could not be written (read-only).""",
    "doctor": """\
    Check the set-up before a bring-up: profile, ports, buses, routes, targets.

    One line per check with the fix to type; exit 0 only when all pass. Without -p: the
    -t URLs, or what each transport finds on this host (its ports and buses).""",
    "stream": """\
    Stream every block's state interfaces: a live table on a terminal (fitted to it; the
    rows that do not fit are counted, -i picks fewer), NDJSON with --json or when piped; with
    --foxglove, to Foxglove as well (every interface, whatever -i picks). Exit 4 when a link
    is down at the end, 3 when one was lost and came back.""",
    "home": """\
    Drive every block's joints home: by their homing routine, or to the home pose.

    Joints with a `home` command interface (the Bioscara arm) run into their hard stops one at
    a time, in the profile's homing order; the others go to safety.home_pose (zero unless the
    profile says otherwise). Blocks that cannot home are named.""",
    "jog": """\
    Move one joint by DELTA (or --to POS), within its limits and the profile's jog step;
    more JOINT DELTA pairs move at the same time (blocks on several links at once).

    A bare number is in rad for a revolute joint, m for a prismatic one; 5deg, 2mm say
    their unit, and a unit that is not the joint's (an angle on a prismatic joint) is
    refused (exit 2). The confirmation shows the move in the unit typed (else degrees or
    millimetres).""",
    "ports": """\
    List the adapters a robot hangs on: serial, CAN and I2C.

    Each serial adapter with its stable path (/dev/serial/by-id/…) or usb:VID:PID:SERIAL
    target, USB IDs, driver, FTDI latency timer, the rates its driver refuses, access and who
    holds it; each CAN interface with its state, bit rate and error counters; each I2C
    adapter by name. Nothing is opened or sent.""",
    "replay": """\
    Play a recording's commands back at their recorded timing, then report per joint the
    difference between recorded and replayed position (RMS, max).

    The profile is the recording's own (its metadata), or -p PROFILE. Every command is
    checked against the profile's limits and jog step before anything moves; then the
    joints go to the recorded start pose; then the commands follow, and a joint that leaves
    its limits or strays beyond --max-deviation from the recording stops every block
    (exit 5). Runs on the profile's simulators unless --device (with --yes, or confirmed on
    a terminal, --sim too): then on the device -t names, under the limits of -p PROFILE or of the
    catalog's profile of the recorded name; a recorded profile looser than that is refused
    (exit 5).""",
    "report": """\
    Run the acceptance sequence and write one self-contained HTML report and its JSON
    twin: identity of every block and the bus scan, the configuration's fingerprint (and with
    --golden its differences), link quality per block, the sensors verified (IMU self-test
    and gravity, F/T residuals after a tare), plots of a recording, a sign-off block and the
    report's hash. With --yes, motion checks where the profile allows motion: returns home
    and each joint to its soft limits and back. Limits come from the profile's `report:`
    section. Exit 0 when every check passes, 1 when one fails (named), 3 with warnings.""",
    "sim serve": """\
    Serve every block's simulated device until Ctrl-C or SIGTERM, printing one target per
    bus (--target 'BUS=URL', quoted for a POSIX shell; --env: one export line).

    Each family's emulator serves its blocks behind a real link, with the faults and settings
    the family declares (below). --hardware serves some blocks only; --json prints one line.
    A device that can be turned or moved from outside answers control lines on the standard
    input, one a line (face -x, hand elbow_flex 30 …); the line help lists them.

    While it runs, --sim of the same profile (same content and faults) drives it instead of
    starting a simulator of its own, so a robot homed by one command stays homed for the
    next; --sim-fresh or --private keep them apart.""",
    "record": """\
    Record every block's state interfaces; Ctrl-C, SIGTERM, SIGHUP or --duration end with a
    valid file. Exit 4 when a link is down at the end, 3 when one was lost and came back, 1 when
    the file could not be written to the end (disk full, file too large, removed).""",
    "info": """\
    What a recording holds: its times, blocks and their identities, topics with counts and
    rates, link losses and gaps with their times, the loop's lateness and jitter. Reads the
    file's summary and index, not every message.""",
    "plot": """\
    Interfaces over time: in the terminal (plotext), or as a figure with --out
    (matplotlib). Reads only the topics that carry them. Needs pip install 'deltoctl\\[plot]'.""",
    "help": """\
    Show the help of deltoctl, of a verb, of a topic (targets, the trust model, security,
    shell completion, exit codes …), the shipped examples, or the JSON Schema of a verb's
    --json document.""",
    "profile tests": """\
    Write a starting pytest suite for a robot: identify, detect, its configuration against
    a golden snapshot (taken of the simulators), link quality and homing. It passes on the
    simulators as written, and runs on the robot with --deltoctl-target (`deltoctl help pytest`).
    """,
    "config snapshot": """\
    Read every configurable value of every block (--hardware narrows) into one YAML file:
    the whole control table of each servo, the Bioscara joints' parameters, the gripper's
    firmware and sensors, the IMU's registers. --json prints the document.""",
}


# the help of the options whose text runs past two lines, by command path and option (or
# argument)
OPTION_HELP = {
    "config restore --allow": (
        "Permit what a restore does not do unasked (repeatable): torque-off (switch a servo's "
        "torque off for its EEPROM writes, on again after), home-offset (write a joint's stored "
        "home offset), or a safety setting by its item name, e.g. max-position-limit (limits, "
        "shutdown, homing offset and modes are written only when named)."),
    "record --foxglove-origin": (
        "Also let in browser pages of this origin (repeatable, e.g. http://localhost:8080 for a "
        "self-hosted Foxglove); by default only Foxglove's own (https://app.foxglove.dev, the "
        "desktop app) and clients that send no Origin."),
    "record OUTPUT": (
        "The .mcap file to write; {time} in its name becomes the start time (UTC, "
        "20261125T211400Z), {serial} each block's device serial, or its target's address where "
        "the device reports none (joined by +)."),
    "record --gpio-type": (
        "/gpio's type: group-values (control_msgs/DynamicInterfaceGroupValues, control_msgs 4.7+ "
        "on Humble, 5.3+ on Jazzy) or joint-state (control_msgs/DynamicJointState, every "
        "control_msgs)."),
    "jog --record": (
        "Record the motion to MCAP: every block's states and each cycle's commands "
        "(/joint_commands), for `deltoctl replay`; {time} and {serial} in its name are filled as "
        "record fills them."),
}


def _documented(param: Any) -> Any:
    """A copy of a root option that only shows in a verb's help (and completes there): the
    value itself is hoisted to the root before any parsing, so the copy never receives one."""
    import copy

    doc = copy.copy(param)
    doc.name = f"global_{param.name}"  # apart from a verb's own (torque's TARGET argument)
    doc.expose_value = False
    doc.callback = None
    doc.is_eager = False
    doc.envvar = None  # read once, by the root
    doc.show_envvar = False
    doc.rich_help_panel = GLOBAL_PANEL
    return doc


def teach_verbs(root: Any, loaded: dict[str, Any]) -> None:
    """Teach the verbs just loaded by the root group: their panel (their stage) and line in
    its help."""
    from deltoctl.render.manpages import summary

    globals_ = [_documented(p) for p in root.params if p.name not in _NOT_GLOBAL]
    for name, command in loaded.items():
        teach(command, name, globals_)
        command.rich_help_panel = verbs.TITLES.get(verbs.TABLE[name].stage)
        command.short_help = summary(command.help)


def teach(command: Any, path: str, globals_: list[Any]) -> None:
    """Give a verb (and its sub-verbs) the global options panel, its effect on the robot
    and its example (from the verb table), and the exit codes."""
    known = {o for p in command.params for o in getattr(p, "opts", ())}
    command.params.extend(p for p in globals_ if not known & set(p.opts))
    command.parse_args = _lenient(command, command.parse_args)
    example = EXAMPLES.get(path)
    command.epilog = (f"Effect: {verbs.describe(path)}.\n\n"
                      + (f"Example: {example}\n\n" if example else "") + EXIT_LINE)
    for name, sub in getattr(command, "commands", {}).items():
        teach(sub, f"{path} {name}", globals_)


def _lenient(command: Any, parse: Any) -> Any:
    """``parse_args`` that, while completing, drops a last option still waiting for its value
    (the one being completed): click would stop there, before the arguments, and
    ``sim serve mh5 --missing <TAB>`` would not know the profile."""
    def parse_args(ctx: Any, args: list[str]) -> list[str]:
        if ctx.resilient_parsing and args and _wants_value(command, args[-1]):
            args = args[:-1]
        return parse(ctx, args)

    return parse_args


def _wants_value(command: Any, arg: str) -> bool:
    return any(arg in p.opts and not (p.is_flag or p.count) for p in command.params
               if getattr(p, "param_type_name", "") == "option")
