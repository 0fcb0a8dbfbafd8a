"""The System: every hardware block of a profile, as ros2_control's resource manager holds them.

One driver per ``<ros2_control>`` block, built from its family's descriptor; each block with
its own lifecycle state, warnings and statistics; every interface routed to its block by name.
A cycle sends every block's read request first, then takes the replies, so blocks on different
links wait for their devices at the same time. Blocks on one link (I2C devices on one bus) share
its transport. Whatever happens, closing leaves every block safe (duty 0, stop, torque as found)
and releases its link.

The safety envelope is the System's, whoever calls it: a move, a command to a joint's
position, velocity or effort interface and a replayed setpoint are checked against the joint's
limits and soft limits, its velocity and effort limits and ``max_jog_step`` (core/envelope.py)
before a byte is sent to any block; a target outside is ``OutsideEnvelope`` (a ``Refused``,
exit 5).
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

from deltoctl import registry, trace
from deltoctl.core import envelope
from deltoctl.core.driver import Block, Driver, Links, MoveResult, Progress, Setpoint
from deltoctl.core.lifecycle import Lifecycle
from deltoctl.errors import DeltoctlError, InvalidInput, Refused, Unreachable
from deltoctl.profile.model import Component, Hardware, Profile
from deltoctl.registry import Family

STATUS = "system/connection_status"  # 1 while every block's link is up


class Member:
    """One block of the System: its driver, lifecycle and where it is."""

    def __init__(self, hw: Hardware, family: Family, driver: Driver,
                 simulated: str | None = None) -> None:
        self.hw, self.family, self.driver = hw, family, driver
        self.simulated = simulated  # why it runs on a simulator ("--sim", a mock param)
        self.name = hw.name
        self.lifecycle = Lifecycle(hw.name)
        self.status_key = f"{hw.name}/connection_status"

    @property
    def url(self) -> str:
        return self.driver.url

    def can(self, capability: str) -> bool:
        return capability in self.family.capabilities


def select_blocks(profile: Profile, names: list[str] | tuple[str, ...] = ()) -> list[Hardware]:
    """The blocks ``--hardware`` names (all when none are named)."""
    if not names:
        return list(profile.hardware)
    known = {hw.name: hw for hw in profile.hardware}
    unknown = [n for n in names if n not in known]
    if unknown:
        from deltoctl.suggest import did_you_mean

        raise InvalidInput(f"--hardware {', '.join(unknown)}: {profile.name} has no such block"
                           f"{did_you_mean(unknown[0], known)}; its blocks: {', '.join(known)}")
    return [hw for hw in profile.hardware if hw.name in names]


def mock_blocks(profile: Profile, names: list[str] | tuple[str, ...] = ()) -> dict[str, str]:
    """The selected blocks whose plugin param asks for the plugin's own mock mode, each with
    that param: they run on their family's emulator. A bus is simulated whole or not at all."""
    mock: dict[str, str] = {}
    for hw in select_blocks(profile, names):
        family = registry.of_block(profile.family_of(hw), hw.plugin)
        if family is not None and family.is_mock(hw.params):
            mock[hw.name] = f"{family.mock_param}: {hw.params[family.mock_param or '']}"
    for hw in select_blocks(profile, names):
        sharing = [o.name for o in profile.hardware
                   if o.bus == hw.bus and o.name != hw.name and o.name in mock]
        if hw.bus and hw.name not in mock and sharing:
            raise InvalidInput(f"{hw.name} is on bus {hw.bus!r} with {', '.join(sharing)}, "
                               "which the profile simulates (mock hardware): a bus is "
                               "simulated whole or not at all", hint="use --sim, or "
                               "--hardware to leave one of them out")
    return mock


def parse_targets(profile: Profile, targets: list[str] | tuple[str, ...]) -> tuple[dict, list]:
    """``--target`` values: ``BUS=URL`` by bus name, and bare URLs."""
    named: dict[str, str] = {}
    bare: list[str] = []
    for item in targets:
        name, found, url = item.partition("=")
        if found and (":" not in name or name in profile.buses):
            if name not in profile.buses:
                from deltoctl.suggest import did_you_mean

                raise InvalidInput(f"--target names unknown bus {name!r}"
                                   + (did_you_mean(name, profile.buses) or
                                      f" (the profile's buses: {', '.join(profile.buses)})"))
            named[name] = url
        else:
            bare.append(item)
    return named, bare


def _name_frames(profile: Profile, hw: Hardware, family: Family, url: str) -> None:
    """The -vv trace names the block's frames with its family's codec (on an I2C bus, those
    of its parts' addresses)."""
    from deltoctl.profile.validate import part_address

    addresses = [part_address(profile, hw, c) for c in hw.components()]
    trace.name_frames(url, family.frame_namer(), [a for a in addresses if a is not None],
                      registry.trace_label(url))


def _with_scheme(url: str, hw: Hardware, family: Family) -> str:
    """A target as given, when it has a scheme; one without is an error that suggests the
    URL of the block's family's transport (``/dev/ttyUSB0`` → ``serial:///dev/ttyUSB0``)."""
    if "://" in url or any(url.startswith(f"{s}:") for s in family.schemes):  # usb:VID:PID
        return url
    from deltoctl.transport import url_hint

    near = next((h for s in family.schemes if (h := url_hint(url, s))), "")
    raise InvalidInput(f"{url!r} is not a target URL (no scheme) for {hw.name}{near}",
                       hint="a target is a URL: " + ", ".join(f"{s}://…" for s in family.schemes))


class System:
    """``with System(profile, targets) as system: system.read()``."""

    def __init__(self, profile: Profile, targets: list[str] | tuple[str, ...] = (),
                 hardware: list[str] | tuple[str, ...] = (), *, probe: bool = False,
                 allow_model_mismatch: bool = False,
                 simulated: dict[str, str] | None = None, allow_motion: bool = True) -> None:
        """``probe``: a bus where nothing answers is still opened (for ``detect``);
        ``simulated``: the blocks served by an emulator, each with why; without
        ``allow_motion`` every command, move and actuation is refused before a byte is sent
        (the robot under a pytest run without --deltoctl-allow-motion)."""
        self.profile = profile
        self.allow_motion = allow_motion
        self.links = Links()
        self.members: list[Member] = []
        self.notes: list[str] = []  # the System's own warnings (blocks left out)
        self.values: dict[str, float] = {STATUS: 0.0}
        blocks = select_blocks(profile, hardware)
        named, bare = parse_targets(profile, targets)
        buses = {hw.bus for hw in blocks if hw.bus}
        if len(bare) > 1 or (bare and len(buses) > 1):
            raise InvalidInput(f"{profile.name} has several buses ({', '.join(sorted(buses))}): "
                               "name each target, --target BUS=URL")
        for hw in blocks:
            family = registry.of_block(profile.family_of(hw), hw.plugin)
            if family is None:
                self.notes.append(f"{hw.name} left out: no driver family for plugin "
                                  f"{hw.plugin!r} (families: {', '.join(registry.families())})"
                                  + registry.install_hint(plugin=hw.plugin))
                continue
            url = self._url(hw, family, named, bare)
            block = Block(profile, hw, family, url, probe, allow_model_mismatch, self.links,
                          self.values)
            self.members.append(Member(hw, family, family.driver_class()(block),
                                       (simulated or {}).get(hw.name)))
            if trace.PACKETS:  # -vv: the family's codec names the frames on its link
                _name_frames(profile, hw, family, url)
        if not self.members:
            raise InvalidInput(f"{profile.name}: no block deltoctl can drive "
                               f"({'; '.join(self.notes) or 'the profile has no blocks'})")
        self._owner: dict[str, Member] = {c.name: m for m in self.members
                                          for c in m.hw.components()}
        self._followed: dict[str, float] = {}  # each joint's last replayed position setpoint

    def _url(self, hw: Hardware, family: Family, named: dict, bare: list) -> str:
        if not family.schemes:
            return ""  # no transport (a mock)
        given = named.get(hw.bus, bare[0] if bare else None)
        if given is not None:
            return _with_scheme(str(given), hw, family)
        if hw.bus is None or hw.bus not in self.profile.buses:
            raise InvalidInput(f"{hw.name!r} has no bus URL: pass --target URL")
        return self.profile.buses[hw.bus]

    # -- lifecycle ---------------------------------------------------------------------------
    def __enter__(self) -> System:
        try:
            self.configure()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def configure(self) -> None:
        """Configure and activate every block (at the same time: an unreachable one costs its
        timeout once, not once per block). A sensor block that cannot be reached is left out
        with a warning; any other unreachable block is an error naming it."""
        errors: dict[str, BaseException] = {}

        def bring_up(m: Member) -> None:
            try:
                m.lifecycle.transition("configure", m.driver.configure)
                m.lifecycle.transition("activate", m.driver.activate)
            except BaseException as exc:
                errors[m.name] = exc

        threads = [threading.Thread(target=bring_up, args=(m,), daemon=True)
                   for m in self.members[1:]]
        for t in threads:
            t.start()
        bring_up(self.members[0])
        for t in threads:
            t.join()
        for m in list(self.members):
            exc = errors.get(m.name)
            if isinstance(exc, Unreachable) and m.hw.type == "sensor" and len(self.members) > 1:
                self.notes.append(f"{m.name} left out: {exc.message}")
                self.members.remove(m)
                del errors[m.name]
        for exc in errors.values():
            if not isinstance(exc, Exception):
                raise exc  # Ctrl-C
        unreachable = {n: e for n, e in errors.items() if isinstance(e, Unreachable)}
        other = [e for e in errors.values() if not isinstance(e, Unreachable)]
        if other:  # a wrong target or a device that answers wrongly says more than silence
            raise other[0]
        if unreachable:
            others = [m.name for m in self.members if m.name not in errors]
            hint = next(iter(unreachable.values())).hint
            if others:
                hint = f"--hardware {' --hardware '.join(others)} works on the others"
            raise Unreachable("; ".join(f"{n}: {e.message}" if n not in e.message else e.message
                                        for n, e in unreachable.items()), hint=hint)
        self._owner = {c.name: m for m in self.members for c in m.hw.components()}

    def close(self) -> None:
        """Leave every block safe, then release it (runs on errors and Ctrl-C too)."""
        try:
            for m in self.members:
                m.driver.halted.set()
            for m in self.members:
                try:
                    if m.lifecycle.state == "active":
                        m.lifecycle.transition("deactivate", m.driver.deactivate)
                    if m.lifecycle.state == "inactive":
                        m.lifecycle.transition("cleanup", m.driver.cleanup)
                    else:
                        m.driver.cleanup()
                    m.lifecycle.transition("shutdown")
                except DeltoctlError as exc:
                    self.notes.append(f"{m.name}: {exc.message} while closing")
        finally:
            self.links.close()

    # -- lookups ---------------------------------------------------------------------------
    def __iter__(self) -> Iterator[Member]:
        return iter(self.members)

    def member(self, part: str) -> Member:
        """The block a joint, sensor or GPIO (or one of its interfaces) belongs to."""
        name = part.rpartition("/")[0] if "/" in part else part
        m = self._owner.get(name)
        if m is None:
            where = [hw.name for hw in self.profile.hardware
                     if any(c.name == name for c in hw.components())]
            if where:
                raise InvalidInput(f"{name} is in block {where[0]}, which this command does "
                                   "not drive (see --hardware)")
            from deltoctl.suggest import did_you_mean

            names = [c.name for hw in self.profile.hardware for c in hw.components()]
            raise InvalidInput(f"{self.profile.name} has no joint, sensor or GPIO {name!r}"
                               + did_you_mean(name, names))
        return m

    def component(self, name: str) -> Component:
        return next(c for c in self.member(name).hw.components() if c.name == name)

    def able(self, capability: str) -> list[Member]:
        return [m for m in self.members if m.can(capability)]

    def state_interfaces(self) -> list[str]:
        """Every state interface of the driven blocks, the drivers' extras, and the links'."""
        names = [n for m in self.members for c in m.hw.components()
                 for n in c.interface_names("state")]
        return [*names, *self.extra_states(), *(m.status_key for m in self.members), STATUS]

    def extra_states(self) -> list[str]:
        return [f"{j.name}/{e}" for m in self.members for j in m.hw.joints
                for e in m.driver.extra_states]

    @property
    def url(self) -> str:
        return ", ".join(m.url for m in self.members if m.url) or "in-process"

    @property
    def connected(self) -> bool:
        return all(m.driver.connected for m in self.members)

    @property
    def stats(self) -> dict[str, int]:
        return {k: sum(m.driver.stats[k] for m in self.members)
                for k in ("packets", "errors", "reconnects")}

    def warnings(self) -> list[str]:
        found = list(self.notes)
        for m in self.members:
            found += m.driver.warnings
            if m.driver.stats.get("reconnects"):
                found.append(f"{m.name}: the link was lost and re-established "
                             f"{m.driver.stats['reconnects']} time(s)")
        return found

    def comm_loops(self) -> list[Any]:
        return [loop for m in self.members for loop in m.driver.comm_loops()]

    # -- the cycle ---------------------------------------------------------------------------
    def read(self) -> dict[str, float]:
        """One cycle's state of every block: requests out on every link, then the replies."""
        members = self.members
        for m in members:
            m.driver.start_read()
        values = self.values  # the drivers' own dict: they store into it
        up = 1.0
        for m in members:
            m.driver.read()
            ok = 1.0 if m.driver.connected else 0.0
            values[m.status_key] = ok
            up = min(up, ok)
        values[STATUS] = up
        return values

    def check_allowed(self, what: str) -> None:
        """Refused when this System allows no motion or actuation (``allow_motion``)."""
        if not self.allow_motion:
            raise Refused(f"{what}: this robot allows no motion or actuation",
                          "run pytest with --deltoctl-allow-motion to let its tests move the "
                          "robot and switch its outputs")

    def set_command(self, name: str, value: float) -> None:
        """One command interface by name (``joint/position``, ``gpio/output_1``). A joint's
        position, velocity or effort command is checked against the envelope first: a
        position as a move from where the joint is (``max_jog_step``)."""
        self.check_allowed(f"command {name}")
        m = self.member(name)
        part, _, interface = name.rpartition("/")
        comp = self.component(part or name)
        if comp.kind == "joint":
            present = self._positions([part]) if interface == "position" else {}
            envelope.check_command(self.profile, comp, interface, value, present.get(part),
                                 m.driver.effort_cap())
        m.driver.write({name: value})

    def stop(self, blocks: Iterable[str] | None = None) -> None:
        """Each block's safe state (every block's, or only those named in ``blocks``: a
        block a command never reached is left as it is)."""
        self._followed.clear()
        for m in self.members:
            if blocks is None or m.name in blocks:
                m.driver.stop()

    def make_safe(self) -> None:
        """Every block's safe state, whatever this session sent: what the fleet's agent does
        after killing a motion verb that had no time for its own stop."""
        self._followed.clear()
        for m in self.members:
            m.driver.make_safe()

    # -- motion ----------------------------------------------------------------------------
    def by_block(self, joints: list[str] | dict[str, float]) -> dict[str, list[str]]:
        """Joint names grouped by their block, in the profile's order of blocks."""
        groups: dict[str, list[str]] = {}
        for j in joints:
            groups.setdefault(self.member(j).name, []).append(j)
        return {m.name: groups[m.name] for m in self.members if m.name in groups}

    def _positions(self, joints: Iterable[str]) -> dict[str, float]:
        """Each joint's position as last read (read first when one is not known yet); a
        joint whose position is still unknown is left out."""
        keys = {j: f"{j}/position" for j in joints}
        if any(k not in self.values for k in keys.values()):
            self.read()
        return {j: self.values[k] for j, k in keys.items() if k in self.values}

    def _joint(self, name: str) -> Component:
        comp = self.component(name)
        if comp.kind != "joint":
            raise InvalidInput(f"{name} is a {comp.kind}, not a joint: it does not move")
        return comp

    def check_move(self, targets: Mapping[str, float], velocity: float | None = None, *,
                   jog: bool = True) -> None:
        """Refuse (``OutsideEnvelope``, exit 5) a move that leaves the envelope, before anything
        is sent: a target outside a joint's limits or soft limits, a velocity beyond its limit,
        a step beyond ``max_jog_step`` from where the joint is (its last read). ``jog``
        False: a move to a known pose (``home``, a replay's start pose), within the limits
        but not bounded by ``max_jog_step``."""
        if not targets:
            raise InvalidInput("a move needs a target for at least one joint")
        bounded = jog and self.profile.safety.max_jog_step is not None
        present = self._positions(targets) if bounded else {}
        for joint, target in targets.items():
            envelope.check_move(self.profile, self._joint(joint), target, present.get(joint),
                              velocity, jog)

    def check_ready(self, joints: Iterable[str]) -> None:
        """Refuse (``Refused``) a move of ``joints`` that a block's motion rules forbid now
        (homed first …), before anything is sent."""
        for names in self.by_block(list(joints)).values():
            self.member(names[0]).driver.check_motion(names)

    def follow(self, setpoints: Mapping[str, Setpoint]) -> None:
        """One cycle's setpoints (a replay's row) to the blocks that hold their joints, once
        every one is within the envelope: its position a ``max_jog_step`` at most from the
        setpoint before (the first: from where the joint is), its velocity and effort within
        the joint's limits (the family clamps an effort to its cap, as its moves do).
        ``stop`` forgets the setpoints before."""
        self.check_allowed("following setpoints")
        before = self._followed
        fresh = [j for j in setpoints if j not in before]
        present = self._positions(fresh) if fresh else {}
        members = []
        for joint, setpoint in setpoints.items():
            m = self.member(joint)
            envelope.check_setpoint(self.profile, self._joint(joint), setpoint,
                                  before.get(joint, present.get(joint)))
            if m not in members:
                members.append(m)
        for m in members:
            m.driver.follow({j: sp for j, sp in setpoints.items() if self._owner[j] is m})
        before.update((j, sp[0]) for j, sp in setpoints.items() if sp[0] == sp[0])

    def move(self, targets: dict[str, float], velocity: float | None = None,
             progress: Progress | None = None, *, jog: bool = True) -> MoveResult:
        """Each block moves its joints; blocks on different links move at the same time.
        Ctrl-C or an error in one block halts them all. Every target is checked first
        (``check_move``), and every block's motion rules (homed first): a refused one sends
        nothing to any block."""
        self.check_allowed(f"moving {', '.join(targets)}")
        self.check_move(targets, velocity, jog=jog)
        self.check_ready(targets)
        self._followed.clear()
        groups = self.by_block(targets)
        members = {m.name: m for m in self.members}
        for m in self.members:
            m.driver.halted.clear()
        if len(groups) == 1:
            name, joints = next(iter(groups.items()))
            return members[name].driver.move({j: targets[j] for j in joints}, velocity,
                                            progress)
        fractions = dict.fromkeys(groups, 0.0)
        results: dict[str, MoveResult] = {}
        errors: list[BaseException] = []

        def run(name: str, joints: list[str]) -> None:
            def report(fraction: float) -> None:
                fractions[name] = fraction
                if progress:
                    progress(min(fractions.values()))

            try:
                results[name] = members[name].driver.move({j: targets[j] for j in joints},
                                                          velocity, report)
            except BaseException as exc:
                errors.append(exc)
                for m in members.values():
                    m.driver.halted.set()

        threads = [threading.Thread(target=run, args=item, daemon=True)
                   for item in groups.items()]
        try:
            for t in threads:
                t.start()
            for t in threads:
                while t.is_alive():
                    t.join(0.05)  # short waits: Ctrl-C reaches this thread
        except BaseException:
            for m in members.values():
                m.driver.halted.set()
            for t in threads:
                t.join()
            raise
        if errors:
            raise errors[0]
        return MoveResult(all(r.settled for r in results.values()),
                          max(r.seconds for r in results.values()),
                          {j: e for r in results.values() for j, e in r.errors.items()},
                          [j for r in results.values() for j in r.unsettled])
