"""The figures of deltoctl's benchmarks (deltoctl/benchmarks/) for people, a line each:
``bench loop``'s runs, ``bench dynamixel``'s sync reads against the SDK and the wire, and
``bench i2c``'s transactions against the I2C wire time."""

from __future__ import annotations

from typing import Any


def loop_lines(results: dict[str, Any], counts: tuple[int, ...], rate: float) -> list[str]:
    """The idle loop's baseline, each number of hands' runs, and the goals met."""
    import os

    per = results["hands_per_process"]
    lines = [f"bench loop: {results['profile']}, {', '.join(map(str, counts))} hand(s), served "
             "by " + ("one sim serve process" if per is None else f"sim serve, {per} to a process")
             + f" ({os.cpu_count()} CPUs)"]
    idle = results["idle_loop"]
    lines.append(f"  baseline: an idle {rate:g} Hz loop here reaches "
                 f"{100 * idle['achieved_fraction']:.2f} %, lateness p99 "
                 f"{idle['lateness_p99_ms']:.3f} ms, misses {idle['deadline_misses']}"
                 + _steal(idle))
    for n, run in results["hands"].items():
        for name in ("paced", "paced_foxglove", "unpaced"):
            if name in run:
                lines += run_lines(n, "+foxglove" if name == "paced_foxglove" else name,
                                   run[name])
            calls = run.get("syscalls") if name == "paced" else None
            if calls:
                by_call = ", ".join(f"{k} {v:g}" for k, v in calls["by_call"].items())
                lines.append(f"      system calls of the loop thread per paced cycle (strace): "
                             f"{calls['per_cycle']:g} ({by_call})")
    lines.append("  goals: " + ", ".join(f"{k}={'yes' if v else 'NO'}"
                                         for k, v in results["goals"].items()))
    return lines


def _steal(r: dict[str, Any]) -> str:
    return f", CPU steal {r['cpu_steal_percent']} %" if r["cpu_steal_percent"] is not None else ""


def run_lines(n: str, label: str, r: dict[str, Any]) -> list[str]:
    """One run's rate, lateness and jitter; its cost per cycle by stage and by process."""
    stages = ", ".join(f"{k} {v:.1f}" for k, v in r["stage_us_per_cycle"].items())
    lines = [
        f"  {n} hand(s) {label:9} requested {r['requested_rate']:g} Hz, real "
        f"{r['real_rate']:.1f} Hz"
        + (f" ({100 * r['achieved_fraction']:.2f} %)" if r["achieved_fraction"] else "")
        + f", lateness p50 {r['lateness_p50_ms']:.3f} ms p99 {r['lateness_p99_ms']:.3f} ms, "
        f"period jitter p99 {r['period_jitter_p99_ms']:.3f} ms, misses {r['deadline_misses']}, "
        f"errors {r['errors']}" + _steal(r),
        f"      µs per cycle: {stages}; CPU {r['cpu_us_per_cycle']:.1f} in the loop, "
        f"{r['recorder_process_cpu_us_per_cycle']:.1f} in the recorder process "
        f"({r['recorder_process_cycles_cpu_us_per_cycle']:.1f} its cycles', "
        f"{r['recorder_process_setup_cpu_ms']:.1f} ms to start and finish the file)",
        f"      the loop thread: CPU {r['loop_thread_cpu_us_per_cycle']:.1f} µs per cycle, "
        f"{r['loop_cpu_us_per_hand_cycle']:.1f} per hand; "
        f"{r['loop_wakeups_per_cycle']:g} wake-ups per cycle"]
    if "foxglove" in r:
        f = r["foxglove"]
        lines.append(f"      Foxglove: {f['cycles_sent']} cycles sent, {f['cycles_dropped']} "
                     f"dropped; the client got {f['client_messages']} messages, /joint_states "
                     f"at {f['client_joint_states_per_s']:.1f} Hz (its process: "
                     f"{f['client_cpu_percent']} % of a CPU)")
    return lines


def dynamixel_lines(results: dict[str, Any], servos: int) -> list[str]:
    """Sync reads of ``servos`` servos: against dynamixel-sdk, paced against the wire's limit,
    on two buses at once, and on a bus of mixed models."""
    lines = [f"sync read 126/10 of {servos} servos, emulator in another process:",
             f"  deltoctl       {results['deltoctl_hz']:8.1f} cycles/s "
             f"({results['deltoctl_errors']} errors)"]
    if "dynamixel_sdk_hz" in results:
        lines.append(f"  dynamixel-sdk  {results['dynamixel_sdk_hz']:8.1f} cycles/s "
                     f"({results['dynamixel_sdk_errors']} errors)   ratio {results['ratio']:.2f}")
    for baud, p in results["paced"].items():
        lines.append(f"  paced at {int(baud) // 1000} kbps: {p['deltoctl_hz']:.1f} cycles/s of "
                     f"a {p['wire_limit_hz']:.1f} wire limit = {100 * p['fraction']:.1f} % "
                     f"({p['errors']} errors)")
    two = results["two_buses"]
    lines.append(f"  two buses ({' + '.join(map(str, two['servos']))} servos) paced at "
                 f"{two['baud'] // 1000} kbps, one System cycle: {two['both_ms']:.3f} ms = "
                 f"{two['both_over_slower_wire']:.3f} × the slower bus's wire time "
                 f"({max(two['wire_ms'].values()):.3f} ms); one after the other: "
                 f"{two['in_series_ms']:.3f} ms = {two['in_series_over_slower_wire']:.3f} ×")
    mixed = results["mixed_bus"]
    lines.append(f"  mixed bus (5 × XM430 + 2 × XL330) at 1 kHz, paced at "
                 f"{mixed['baud'] // 1000} kbps: "
                 + ", ".join(f"{k.replace('_', ' ')} {v['mean_ms']:.3f} ms" for k, v in
                             mixed["reads"].items())
                 + f"; Sync Read = {mixed['sync_read_over_wire']:.3f} × its wire time "
                   f"({mixed['wire_ms']['sync_read']:.3f} ms), "
                   f"{mixed['sync_read_less_pty_over_wire']:.3f} × less the pseudo-terminal's "
                   f"round trip ({mixed['pty_round_trip_ms']['mean']:.3f} ms)")
    limit = mixed["flat_out_wire_limit_hz"]["sync_read"]
    if "ratio_to_sdk" in mixed:
        lines.append(f"  flat out, paced: deltoctl {mixed['deltoctl_flat_out_hz']:.1f} reads/s "
                     f"(the wire's limit {limit:.1f}), dynamixel-sdk GroupBulkRead "
                     f"{mixed['dynamixel_sdk_bulk_read_hz']:.1f}: "
                     f"ratio {mixed['ratio_to_sdk']:.2f}")
    unpaced = mixed["unpaced"]
    if "ratio_to_sdk" in unpaced:
        cpu = unpaced["cpu_us_per_read"]
        lines.append(f"  flat out, unpaced: deltoctl {unpaced['deltoctl_sync_read_hz']:.1f} "
                     f"reads/s ({cpu['deltoctl_sync_read']:.0f} µs CPU each), dynamixel-sdk "
                     f"GroupBulkRead {unpaced['dynamixel_sdk_bulk_read_hz']:.1f} "
                     f"({cpu['dynamixel_sdk_bulk_read']:.0f} µs CPU each): ratio "
                     f"{unpaced['ratio_to_sdk']:.2f}")
    if "protocol1" in results:
        lines += protocol1_lines(results["protocol1"])
    return lines


def protocol1_lines(p1: dict[str, Any]) -> list[str]:
    """A Protocol 1.0 bus read servo by servo: paced against its wire time, and against
    dynamixel-sdk's Protocol 1.0 reads."""
    lines = [f"Protocol 1.0: {p1['servos']} × {p1['model']} read in turn (36, 8 bytes) at "
             f"{p1['baud'] // 1000} kbps, wire limit {p1['wire_limit_hz']:.1f} cycles/s "
             f"({p1['wire_ms']:.3f} ms a cycle):"]
    for key in ("paced", "unpaced"):
        run = p1[key]
        line = f"  {key}: deltoctl {run['deltoctl_hz']:.1f} cycles/s"
        if "fraction_of_wire" in run:
            line += f" = {100 * run['fraction_of_wire']:.1f} % of the wire's limit"
        if "ratio_to_sdk" in run:
            line += (f", dynamixel-sdk {run['dynamixel_sdk_hz']:.1f}: ratio "
                     f"{run['ratio_to_sdk']:.2f}")
        lines.append(line)
    return lines


def i2c_lines(results: dict[str, Any], cycles: int, clock: int) -> list[str]:
    """The read cycle's time per transaction: the wire's, deltoctl's, smbus2's by hand, the
    emulator's."""
    return [f"read cycle of {results['joints']} Bioscara joints "
            f"({results['transactions_per_cycle']} transactions), {cycles} cycles, I2C wire "
            f"time at {clock / 1000:g} kHz:",
            f"  wire time          {results['wire_us']:8.2f} µs per transaction",
            f"  deltoctl           {results['deltoctl_us']:8.2f} µs "
            f"({results['overhead_pct_of_wire']} % of the wire time; goal ≤ 25 %)",
            f"  smbus2 by hand     {results['smbus2_loop_us']:8.2f} µs",
            f"  emulator (apart)   {results['emulator_us']:8.2f} µs"]


def feetech_lines(results: dict[str, Any]) -> list[str]:
    """Sync reads of an SO arm's bus: deltoctl beside scservo_sdk, paced and unpaced."""
    lines = [f"sync read {results['item']} of {results['servos']} STS3215, emulator in another "
             f"process; the wire's limit at {results['baud'] // 1000} kbps: "
             f"{results['wire_limit_hz']:.1f} reads/s"]
    for name in ("deltoctl", "scservo_sdk"):
        if name in results:
            r = results[name]
            lines.append(f"  {name:12} paced {r['paced_hz']:8.1f} reads/s "
                         f"({100 * r['paced_fraction_of_wire']:.1f} % of the wire's limit); "
                         f"unpaced {r['unpaced_hz']:8.1f} reads/s, "
                         f"{r['cpu_us_per_read']:.1f} µs CPU a read")
    less = [f"{name} {100 * results[name]['paced_fraction_less_pty']:.1f} %"
            for name in ("deltoctl", "scservo_sdk")
            if results.get(name, {}).get("paced_fraction_less_pty") is not None]
    if "pty_round_trip_us" in results:
        lines.append(f"  the pseudo-terminal's own round trip {results['pty_round_trip_us']:.1f} "
                     "µs a read (a real bus has none)"
                     + (f"; less it, paced: {', '.join(less)} of the wire's limit" if less else ""))
    if "paced_ratio" in results:
        lines.append(f"  deltoctl / scservo_sdk: {results['paced_ratio']:.2f} × the reads paced, "
                     f"{results['cpu_ratio']:.2f} × less CPU a read")
    return lines


def scan_lines(results: dict[str, Any]) -> list[str]:
    """Per case, the servo, deltoctl's scan (bus and wall time, what it found) and each SDK
    way's time, medians; a miss of the goal marked."""
    lines = [f"scan of one servo alone on a paced emulated bus, at a rate and in a protocol it "
             f"is not told: medians of {results['runs']} runs (the SDKs' "
             f"{results['sdk_runs']}); goal {results['goal_bus_s']:g} s of bus time"]
    for name, row in results["cases"].items():
        ours = row["deltoctl"]
        bus = "-" if ours["bus_s"] is None else f"{ours['bus_s']:.3f} s"
        what = ", ".join(_found(f) for f in ours["found"]) or f"nothing (exit {ours['exit_code']})"
        goal = "" if row.get("goal_bus_le_1_s", True) else "  (over the goal)"
        lines.append(f"  {name:20} deltoctl  bus {bus:>9}  wall {ours['wall_s']:.3f} s  "
                     f"{ours['probes'] or 0:3} probes  found {what}{goal}")
        for way, sdk in row["sdks"].items():
            found = ", ".join(f"ID {f['id']} at {f['baud']}" for f in sdk["found"]) or "nothing"
            lines.append(f"  {'':20} {way}: {sdk['s']:.3f} s, {sdk['rates_tried']} rate(s), "
                         f"found {found}")
    return lines


def _found(servo: dict[str, Any]) -> str:
    if servo["id"] is None:
        return f"garbled replies at {servo['baud']}"
    return (f"ID {servo['id']} {servo['model'] or '?'} {servo['protocol']} at {servo['baud']}"
            + (" (colliding)" if servo["colliding"] else ""))
