"""Serve the simulated devices of a profile — every block whose family has an emulator — with
the faults asked for. One code path for ``--sim``, ``deltoctl sim serve`` and the pytest
fixture: each family's emulator (named in its descriptor) serves its blocks behind a real
transport and returns each bus's target URL, which the System opens like hardware."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from typing import Any

from deltoctl import registry
from deltoctl.core.emulator_contract import ControlHandler, ServeContext
from deltoctl.errors import InvalidInput
from deltoctl.profile.model import Component, Hardware, Profile
from deltoctl.sim.controls import Controls


class ServeOptions:
    """What serving is asked: where to listen (``host``, ``port``: what every simulator
    shares) and the faults and settings by name (``faults``), each one a family of the
    profile declares (``Family.serve_options``). An emulator reads an option as an attribute
    (``ctx.options.firmware``): its value, or its declaration's default."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, **faults: Any) -> None:
        self.host, self.port = host, port
        self.faults: dict[str, Any] = dict(faults)  # name → value, as given
        self.defaults: dict[str, Any] = {}  # name → the declared default (serve_profile)

    def __getattr__(self, name: str) -> Any:
        for table in ("faults", "defaults"):
            values = self.__dict__.get(table, {})
            if name in values:
                return values[name]
        raise AttributeError(f"no sim option {name!r}")

    def __repr__(self) -> str:
        return f"ServeOptions(host={self.host!r}, port={self.port!r}, faults={self.faults!r})"


class _SimContext:
    """The :class:`~deltoctl.core.emulator_contract.ServeContext` each emulator of a profile
    gets: the options, the stack that closes what it starts, and the simulated I2C buses that
    devices of several families share."""

    def __init__(self, stack: contextlib.ExitStack, profile: Profile, options: ServeOptions,
                 controls: Controls) -> None:
        self.stack, self.profile, self.options = stack, profile, options
        self.blocks: dict[str, dict[str, Any]] = {}  # what each block's emulator reports
        self.controls = controls
        self._i2c: dict[str, tuple[Any, str]] = {}

    def control(self, word: str, usage: str, handler: ControlHandler) -> None:
        self.controls.add(word, usage, handler)

    def named(self, option: str, hw: Hardware) -> list[Component]:
        """The joints of this block that a joint option (``missing`` …) names."""
        names = getattr(self.options, option, ())
        return [j for j in hw.joints if j.name in names]

    def i2c_bus(self, bus: str) -> tuple[Any, str]:
        """``(simulated bus, target URL)`` for a bus name, served once on loopback; each
        family adds its devices to the bus's ``devices``."""
        if bus not in self._i2c:
            from deltoctl.sim.i2c_bus import I2CSocketServer, SimSMBus

            sim = SimSMBus({})
            server = self.stack.enter_context(I2CSocketServer(sim, host=self.options.host))
            self._i2c[bus] = (sim, server.url)
        return self._i2c[bus]


def serve_profile(stack: contextlib.ExitStack, prof: Profile, options: ServeOptions,
                  hardware: list[str] | tuple[str, ...] = (),
                  controls: Controls | None = None) -> dict[str, Any]:
    """Start the simulated devices of the profile's blocks (or of those ``hardware`` names),
    closed with ``stack``; the control lines their emulators answer are added to
    ``controls``. Returns ``{"profile", "buses": {bus: target URL}, "blocks": {block: what
    its emulator reports}}``, ``endpoint`` when there is one bus and ``controls`` (the first
    words of the lines they answer) when there are some."""
    from deltoctl.core.system import select_blocks

    blocks = select_blocks(prof, hardware)
    by_family: dict[str, list[Hardware]] = {}
    families: dict[str, registry.Family | None] = {}
    for hw in blocks:
        family = registry.of_block(prof.family_of(hw), hw.plugin)
        name = family.name if family else prof.family_of(hw) or hw.plugin
        by_family.setdefault(name, []).append(hw)
        families[name] = family
    options = _checked(prof, blocks, options, [f for f in families.values() if f])
    controls = Controls() if controls is None else controls
    ctx: ServeContext = _SimContext(stack, prof, options, controls)
    buses: dict[str, str] = {}
    for name, family in families.items():
        serve = family.emulator_function() if family else None
        if serve is not None:
            buses.update(serve(ctx, by_family[name]))
    if not buses and not any(f and not f.schemes for f in families.values()):
        raise InvalidInput(f"no simulator for the blocks of {prof.name!r} "
                           f"(families: {', '.join(n or 'none' for n in by_family)})")
    result: dict[str, Any] = {"profile": prof.name, "buses": buses, "blocks": ctx.blocks}
    if len(buses) == 1:
        result["endpoint"] = next(iter(buses.values()))
    if controls.words():
        result["controls"] = controls.words()
    return result


_WHERE = ("host", "port", "profile")  # what serving is, not a fault: never a --sim-option


def options_given(items: Sequence[str], what: str, prof: Profile | None = None,
                  hardware: Sequence[str] = ()) -> dict[str, Any]:
    """``NAME=VALUE`` items (``faces=+z:2,-z:2``, ``missing=head_y`` repeated, ``pace`` for a
    flag) as ServeOptions' faults, each value checked later by its declaration; an item not
    of that form, a name no family of ``prof``'s blocks (``hardware``; of any profile
    without) declares — where to listen is not one —, a flag given a value other than true
    or false, or a single-valued option given twice is one InvalidInput naming it."""
    declared = registry.sim_options(_family_names(prof, hardware) if prof else None)
    faults: dict[str, Any] = {}
    for item in items:
        key, has_value, value = item.partition("=")
        name = key.strip().removeprefix("--").replace("-", "_")
        option = None if name in _WHERE else declared.get(name)
        if name and option is None:
            takes = ", ".join(sorted(declared)) or "no options"
            raise InvalidInput(f"{what} {name!r}: not for {prof.name if prof else 'a simulator'}"
                               f" (its simulator takes: {takes})")
        if option is not None and option.kind == "flag":
            if value.lower() not in (("true", "false") if has_value else ("",)):
                raise InvalidInput(f"{what} {item!r}: {option.flag} is on or off: {name} or "
                                   f"{name}=true|false")
            faults[name] = value.lower() != "false"
        elif not name or not has_value:
            raise InvalidInput(f"{what} {item!r} is not of the form NAME=VALUE")
        elif option is not None and option.kind == "joints":
            faults[name] = (*faults.get(name, ()), value)
        elif name in faults:
            raise InvalidInput(f"{what} {name} is given twice")
        else:
            faults[name] = value
    return faults


def _family_names(prof: Profile, hardware: Sequence[str]) -> list[str]:
    """The names of the families of the profile's blocks (or of those ``hardware``)."""
    from deltoctl.core.system import select_blocks

    found = (registry.of_block(prof.family_of(hw), hw.plugin)
             for hw in select_blocks(prof, list(hardware)))
    return [f.name for f in found if f is not None]


def serve_until_stopped(prof: Profile, options: ServeOptions, hardware: Sequence[str],
                        as_json: bool, announce: Callable[[str], None],
                        complain: Callable[[str], None] = print, *, env: bool = False,
                        private: bool = False, note: Callable[[str], None] = print) -> None:
    """Serve the profile's simulated devices until Ctrl-C or SIGTERM (``deltoctl sim serve``).
    Once they are up, ``announce`` is told the targets (``target_lines``; with ``as_json``:
    serve_profile's result on one line). Unless ``private``, ``--sim`` of the same profile
    finds them while they run (sim/running.py); ``note`` is told what cannot be done.
    When the devices answer control lines, each line of the standard input runs one:
    ``announce`` is told its reply (with ``as_json``, ``{"control", "reply"}`` on one line),
    ``complain`` a bad one."""
    import gc
    import json
    import signal
    import sys
    import threading

    from deltoctl.core.system import select_blocks
    from deltoctl.sim.running import registered

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    gc.disable()  # a served device answers within microseconds; no collector pauses
    controls = Controls()
    with contextlib.ExitStack() as stack:
        info = serve_profile(stack, prof, options, list(hardware), controls)
        if not private:
            blocks = [hw.name for hw in select_blocks(prof, hardware)]
            stack.enter_context(registered(prof, options.faults, blocks, info["buses"], note))
        announce(json.dumps(info) if as_json else target_lines(info["buses"], env))

        def reply(line: str, answer: str) -> None:
            announce(json.dumps({"control": line, "reply": answer}) if as_json else answer)

        with contextlib.suppress(KeyboardInterrupt):
            fd = _input_fd(sys.stdin) if controls.words() else None
            if fd is not None:
                if hasattr(signal, "SIGTTIN"):  # in the background: wait, do not stop
                    signal.signal(signal.SIGTTIN, signal.SIG_IGN)
                controls.follow(fd, stop, reply, complain)
            stop.wait()


def target_lines(buses: dict[str, str], env: bool = False) -> str:
    """The targets as a POSIX shell takes them: a ``--target BUS=URL`` line each, quoted (a
    serial URL holds ``&``), or with ``env`` one ``export DELTOCTL_TARGET='BUS=URL …'`` line
    (the targets apart by spaces, as the option reads its variable)."""
    import shlex

    pairs = [f"{bus}={url}" for bus, url in buses.items()]
    if env:
        return f"export DELTOCTL_TARGET={shlex.quote(' '.join(pairs))}"
    return "\n".join(f"--target {shlex.quote(pair)}" for pair in pairs)


def _input_fd(stream: Any) -> int | None:
    """The file descriptor of the standard input, if it has one (not under a test runner)."""
    try:
        return int(stream.fileno())
    except (AttributeError, OSError, ValueError):
        return None


def _checked(prof: Profile, blocks: list[Hardware], options: ServeOptions,
             families: list[registry.Family]) -> ServeOptions:
    """The options with every value as its declaration takes it and every default filled in;
    an option no family of the profile declares (unless left at its default, as a fixture
    passes it), a bad value or a joint the profile does not have is one InvalidInput naming
    it."""
    if not (isinstance(options.port, int) and 0 <= options.port <= 65535):
        raise InvalidInput(f"--port takes 0 to 65535, got {options.port!r}")
    declared = registry.sim_options([f.name for f in families])
    known = registry.sim_options()
    misplaced = [n for n, value in options.faults.items() if n not in declared
                 and (n not in known or value not in (known[n].default, None, (), []))]
    if misplaced:
        flags = [known[n].flag if n in known else repr(n) for n in misplaced]
        allowed = sorted(o.flag for o in declared.values())
        raise InvalidInput(f"{', '.join(flags)}: not for {prof.name} "
                           f"(its simulator takes: {', '.join(allowed) or 'no options'})")
    checked = ServeOptions(options.host, options.port, **{  # another family's default: left out
        name: declared[name].value(value) for name, value in options.faults.items()
        if name in declared})
    checked.defaults = {name: o.default if o.kind != "joints" else ()
                        for name, o in declared.items()}
    joints = {j.name for hw in blocks for j in hw.joints}
    for name, option in declared.items():
        for joint in checked.faults.get(name, ()) if option.kind == "joints" else ():
            if joint not in joints:
                raise InvalidInput(f"{option.flag}: {prof.name} has no joint {joint!r}")
    return checked
