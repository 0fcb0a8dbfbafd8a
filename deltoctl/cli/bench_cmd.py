"""``deltoctl bench loop|dynamixel|i2c``: options, then the figures of deltoctl/benchmarks/
for people (or as JSON)."""

from typing import Annotated

import typer

from deltoctl.cli.context import options
from deltoctl.cli.output import emit_json, say
from deltoctl.errors import InvalidInput

app = typer.Typer(help="Benchmarks that ship with deltoctl.", no_args_is_help=True)


@app.command("loop")
def bench_loop(
    ctx: typer.Context,
    rate: Annotated[float, typer.Option("--rate", help="Requested cycle rate, Hz.")] = 1000.0,
    duration: Annotated[float, typer.Option("--duration", help="Seconds per run.")] = 10.0,
    unpaced: Annotated[float, typer.Option(
        "--unpaced", help="Seconds of the unpaced run (0: skip).")] = 5.0,
    hands: Annotated[str, typer.Option(
        "--hands", help="Numbers of simulated hands to run, e.g. 1,2,4 (each hand served by "
                        "its own process).")] = "1",
    foxglove: Annotated[bool, typer.Option(
        "--foxglove", help="Also the paced run with the live view (record --foxglove) serving "
                           "every topic to a subscribed Foxglove client.")] = False,
    hands_per_process: Annotated[int | None, typer.Option(
        "--hands-per-process", help="Hands each sim serve process serves, one thread "
                                    "answering them (default: all; 1: a process per hand).")
    ] = None,
) -> None:
    """The read+write cycle of N hands while recording, paced and unpaced.

    A gripper profile (default dg-5f-right: F/T and IO), N copies of its block, each against
    its own `sim serve` over loopback TCP, through the cycle runner, recording to MCAP; beside
    it, the same loop idle (what this machine allows). With --foxglove, the paced run again
    while the live view serves it to a Foxglove WebSocket client in another process."""
    from deltoctl.benchmarks.loop import measure

    opts = options(ctx)
    counts = _loop_options(rate, duration, unpaced, hands)
    if hands_per_process is not None and not 1 <= hands_per_process <= 16:
        raise InvalidInput("--hands-per-process takes 1 to 16")
    prof = opts.load_profile(opts.profile or "dg-5f-right")
    results = measure(prof, rate, duration, unpaced, counts, foxglove, hands_per_process)
    if opts.json:
        emit_json(results)
        return
    _say_loop(results, counts, rate)


def _loop_options(rate: float, duration: float, unpaced: float, hands: str) -> tuple[int, ...]:
    """The options checked; the numbers of hands, sorted."""
    import math

    if not all(math.isfinite(x) for x in (rate, duration, unpaced)) or rate <= 0 \
            or duration <= 0 or unpaced < 0:
        raise InvalidInput("--rate and --duration must be positive, --unpaced not negative")
    try:
        counts = tuple(sorted({int(n) for n in hands.split(",") if n.strip()}))
    except ValueError:
        raise InvalidInput(f"--hands takes numbers, e.g. 1,2,4; got {hands!r}") from None
    if not counts or not all(1 <= n <= 16 for n in counts):
        raise InvalidInput("--hands takes 1 to 16 hands")
    return counts


def _say_loop(results: dict, counts: tuple[int, ...], rate: float) -> None:
    import os

    per = results["hands_per_process"]
    say(f"bench loop: {results['profile']}, {', '.join(map(str, counts))} hand(s), served by "
        + ("one sim serve process" if per is None else f"sim serve, {per} to a process")
        + f" ({os.cpu_count()} CPUs)")
    idle = results["idle_loop"]
    say(f"  baseline: an idle {rate:g} Hz loop here reaches {100 * idle['achieved_fraction']:.2f}"
        f" %, lateness p99 {idle['lateness_p99_ms']:.3f} ms, misses {idle['deadline_misses']}"
        + _steal(idle))
    for n, run in results["hands"].items():
        for name in ("paced", "paced_foxglove", "unpaced"):
            if name in run:
                _say_run(n, "+foxglove" if name == "paced_foxglove" else name, run[name])
            calls = run.get("syscalls") if name == "paced" else None
            if calls:
                by_call = ", ".join(f"{k} {v:g}" for k, v in calls["by_call"].items())
                say(f"      system calls of the loop thread per paced cycle (strace): "
                    f"{calls['per_cycle']:g} ({by_call})")
    say("  goals: " + ", ".join(f"{k}={'yes' if v else 'NO'}"
                                for k, v in results["goals"].items()))


def _steal(r: dict) -> str:
    return f", CPU steal {r['cpu_steal_percent']} %" if r["cpu_steal_percent"] is not None else ""


def _say_run(n: str, label: str, r: dict) -> None:
    """One run's rate, lateness and jitter; its cost per cycle by stage and by process."""
    say(f"  {n} hand(s) {label:9} requested {r['requested_rate']:g} Hz, real "
        f"{r['real_rate']:.1f} Hz"
        + (f" ({100 * r['achieved_fraction']:.2f} %)" if r["achieved_fraction"] else "")
        + f", lateness p50 {r['lateness_p50_ms']:.3f} ms p99 {r['lateness_p99_ms']:.3f} ms, "
        f"period jitter p99 {r['period_jitter_p99_ms']:.3f} ms, misses {r['deadline_misses']}, "
        f"errors {r['errors']}" + _steal(r))
    stages = ", ".join(f"{k} {v:.1f}" for k, v in r["stage_us_per_cycle"].items())
    say(f"      µs per cycle: {stages}; CPU {r['cpu_us_per_cycle']:.1f} in the loop, "
        f"{r['recorder_process_cpu_us_per_cycle']:.1f} in the recorder process")
    say(f"      the loop thread: CPU {r['loop_thread_cpu_us_per_cycle']:.1f} µs per cycle, "
        f"{r['loop_cpu_us_per_hand_cycle']:.1f} per hand; "
        f"{r['loop_wakeups_per_cycle']:g} wake-ups per cycle")
    if "foxglove" in r:
        f = r["foxglove"]
        say(f"      Foxglove: {f['cycles_sent']} cycles sent, {f['cycles_dropped']} "
            f"dropped; the client got {f['client_messages']} messages, /joint_states "
            f"at {f['client_joint_states_per_s']:.1f} Hz (its process: "
            f"{f['client_cpu_percent']} % of a CPU)")


@app.command("dynamixel")
def bench_dynamixel(
    ctx: typer.Context,
    servos: Annotated[int, typer.Option(help="Servos on the bus.")] = 11,
    duration: Annotated[float, typer.Option(help="Seconds per measurement.")] = 3.0,
) -> None:
    """Dynamixel sync reads against dynamixel-sdk, and against the wire's limit.

    Present load/velocity/position (126, 10) from N servos of an emulated bus in another
    process: deltoctl's driver against dynamixel-sdk's GroupSyncRead; then, with the bus paced
    at 1 and 2 Mbps, deltoctl's rate against the wire's limit."""
    from deltoctl.benchmarks.dynamixel import measure

    opts = options(ctx)
    if not 1 <= servos <= 252 or duration <= 0:
        raise InvalidInput("--servos must be 1-252 and --duration positive")
    results = measure(servos, duration)
    paced = results["paced"]
    if opts.json:
        emit_json(results)
        return
    say(f"sync read 126/10 of {servos} servos, emulator in another process:")
    say(f"  deltoctl       {results['deltoctl_hz']:8.1f} cycles/s "
         f"({results['deltoctl_errors']} errors)")
    if "dynamixel_sdk_hz" in results:
        say(f"  dynamixel-sdk  {results['dynamixel_sdk_hz']:8.1f} cycles/s "
             f"({results['dynamixel_sdk_errors']} errors)   ratio {results['ratio']:.2f}")
    for baud, p in paced.items():
        say(f"  paced at {int(baud) // 1000} kbps: {p['deltoctl_hz']:.1f} cycles/s of a "
             f"{p['wire_limit_hz']:.1f} wire limit = {100 * p['fraction']:.1f} % "
             f"({p['errors']} errors)")
    two = results["two_buses"]
    say(f"  two buses ({' + '.join(map(str, two['servos']))} servos) paced at "
        f"{two['baud'] // 1000} kbps, one System cycle: {two['both_ms']:.3f} ms = "
        f"{two['both_over_slower_wire']:.3f} × the slower bus's wire time "
        f"({max(two['wire_ms'].values()):.3f} ms); one after the other: "
        f"{two['in_series_ms']:.3f} ms = {two['in_series_over_slower_wire']:.3f} ×")
    mixed = results["mixed_bus"]
    say(f"  mixed bus (5 × XM430 + 2 × XL330) at 1 kHz, paced at {mixed['baud'] // 1000} kbps: "
        + ", ".join(f"{k.replace('_', ' ')} {v['mean_ms']:.3f} ms" for k, v in
                    mixed["reads"].items())
        + f"; Sync Read = {mixed['sync_read_over_wire']:.3f} × its wire time "
          f"({mixed['wire_ms']['sync_read']:.3f} ms)")
    if "ratio_to_sdk" in mixed:
        say(f"  flat out: deltoctl {mixed['deltoctl_flat_out_hz']:.1f} reads/s, dynamixel-sdk "
            f"GroupBulkRead {mixed['dynamixel_sdk_bulk_read_hz']:.1f}: ratio "
            f"{mixed['ratio_to_sdk']:.2f}")


@app.command("i2c")
def bench_i2c(
    ctx: typer.Context,
    cycles: Annotated[int, typer.Option(help="Read cycles per client.")] = 3000,
    clock: Annotated[int, typer.Option(help="I2C clock in Hz for the wire time.")] = 400_000,
) -> None:
    """The Bioscara read cycle against the I2C wire time.

    Position and velocity of bioscara-arm's four joints, each reply with its flags, on the
    in-process emulator: deltoctl's own time per transaction, without the emulator's, against
    the I2C wire time; beside it, the same transactions written straight against smbus2."""
    from deltoctl.benchmarks.i2c import measure

    opts = options(ctx)
    if cycles < 1 or clock <= 0:
        raise InvalidInput("--cycles and --clock must be positive")
    results = measure(cycles, clock)
    if opts.json:
        emit_json(results)
        return
    say(f"read cycle of {results['joints']} Bioscara joints ({results['transactions_per_cycle']} "
         f"transactions), {cycles} cycles, I2C wire time at {clock / 1000:g} kHz:")
    say(f"  wire time          {results['wire_us']:8.2f} µs per transaction")
    say(f"  deltoctl           {results['deltoctl_us']:8.2f} µs "
         f"({results['overhead_pct_of_wire']} % of the wire time; goal ≤ 25 %)")
    say(f"  smbus2 by hand     {results['smbus2_loop_us']:8.2f} µs")
    say(f"  emulator (apart)   {results['emulator_us']:8.2f} µs")


def register(root: typer.Typer) -> None:
    root.add_typer(app, name="bench")
