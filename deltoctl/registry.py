"""The device families deltoctl can drive, found through the ``deltoctl.families`` entry-point
group (the built-in ones are registered in ``pyproject.toml``; a third party adds one by
installing a package that names its descriptor there), and the transports their buses use,
by URL scheme: the built-in ones of ``deltoctl.transport`` and those of the
``deltoctl.transports`` entry-point group (a family's package may bring its own link).

A family owns everything about itself, declared in its descriptor: its codec, driver and
emulator, the schemes of its links, its ``sim serve`` faults (``SimOption``), its restore
permissions (``Permission``), its identity fields and register names. Nothing outside its
folder names it.

A descriptor is data and strings: reading the registry imports each family's small
``__init__`` only; its driver and emulator modules are imported when a block of that family is
opened (``Family.driver_class()``, ``Family.emulator()``), and a transport's module when a link
of its scheme is opened or checked, the way python-can loads an interface only when a bus of
that kind is opened.
"""

from __future__ import annotations

import importlib
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from deltoctl import entry_points
from deltoctl.errors import DeltoctlError, InvalidInput

if TYPE_CHECKING:
    from deltoctl.core.emulator_contract import Emulator
    from deltoctl.transport import Transport

GROUP, TRANSPORTS = entry_points.FAMILIES, entry_points.TRANSPORTS

# what a verb may ask of a driver, beyond the lifecycle and read/write, and the driver
# methods each one calls (a family declaring a capability must have them; "home" moves to
# the home pose, and runs a joint's homing routine where its profile gives it one — a
# ``home`` command interface — or its family says its device has one: ``homing_joints``)
CAPABILITIES: dict[str, tuple[str, ...]] = {
    "identify": ("identify",), "detect": ("detect",), "home": ("move",), "jog": ("move",),
    "calibrate_ft": ("tare_ft",), "gpio": ("set_command",),
    "registers": ("read_registers", "write_register"), "torque": ("set_torque",),
    "reboot": ("reboot",), "config": ("config_read", "config_write"),
    "calibrate_imu": ("sample", "self_test"),
    "calibrate_servos": ("calibrate_servos",),
    "calibrate_joints": ("joint_calibration", "middle_offsets", "positions_under",
                         "write_joint_calibration", "set_torque"),
}

SIM_KINDS = ("flag", "text", "int", "number", "numbers", "steps", "joints")
_NAME = re.compile(r"[a-z][a-z0-9_]{0,31}")
RESERVED = frozenset({"host", "port", "profile"})  # the options every `sim serve` has


@dataclass(frozen=True)
class SimOption:
    """A fault or setting of a family's simulated device: ``deltoctl sim serve --NAME``,
    ``open_robot(sim={"NAME": value})`` and the pytest fixtures' ``NAME=value``. Its emulator
    reads the value as ``ctx.options.NAME`` (the default when not given), and the joints a
    ``joints`` option names as ``ctx.named("NAME", hw)``.

    kind: ``flag`` (on when given), ``text``, ``int`` (0x6A or 106), ``number``, ``numbers``
    (comma-separated, ``count`` of them), ``steps`` (comma-separated ``CHOICE:SECONDS``,
    ``count`` of them, each one of ``choices``: a timed sequence) or ``joints`` (repeatable
    joint names of the profile); ``low``/``high`` bound a number (a step's seconds)."""

    name: str
    kind: str
    help: str
    default: Any = None
    low: float | None = None
    high: float | None = None
    count: tuple[int, int] = (1, 16)  # how many numbers (steps) a ``numbers`` option takes
    choices: tuple[str, ...] = ()  # what a ``steps`` option's steps may name
    metavar: str | None = None

    def __post_init__(self) -> None:
        if not _NAME.fullmatch(self.name) or self.name in RESERVED:
            raise ValueError(f"sim option {self.name!r}: a name of lowercase letters, digits "
                             f"and _ (not {', '.join(sorted(RESERVED))})")
        if self.kind not in SIM_KINDS:
            raise ValueError(f"sim option {self.name!r}: kind must be one of "
                             f"{', '.join(SIM_KINDS)}, got {self.kind!r}")

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def described(self) -> str:
        """Its help, and its default (if any) as a command line gives it: numbers apart by
        commas, a byte in hex."""
        shown = self.default if self.default not in (None, (), False) else None
        if isinstance(shown, tuple):
            shown = ",".join(format(x, "g") for x in shown)
        elif isinstance(shown, int) and self.kind == "int" and self.high == 0xFF:
            shown = f"{shown:#04x}"
        return self.help + (f" Default: {shown}." if shown is not None else "")

    def value(self, given: Any) -> Any:
        """A value given (a command line's text or a program's value) as the emulator takes
        it; anything else is one InvalidInput naming the option and what it takes."""
        try:
            return _CONVERT[self.kind](self, given)
        except (TypeError, ValueError, OverflowError):
            raise InvalidInput(f"{self.flag} takes {_TAKES[self.kind]}"
                               f"{self._bounds()}, got {given!r}") from None

    def _bounds(self) -> str:
        if self.kind in ("numbers", "steps"):
            low, high = self.count
            count = f", {low}" + (f" to {high}" if high != low else "") + " of them"
            each = "" if self.low is None and self.high is None else \
                f", each {_show(self.low)} to {_show(self.high)}"
            if self.kind == "numbers":
                return count + each
            return f" ({'|'.join(self.choices)}){count}{each} s"
        if self.low is None and self.high is None:
            return ""
        return f" from {_show(self.low)} to {_show(self.high)}"

    def _bounded(self, x: float) -> float:
        if not math.isfinite(x) or (self.low is not None and x < self.low) or \
                (self.high is not None and x > self.high):
            raise ValueError(x)
        return x


def _show(bound: float | None) -> str:
    return "…" if bound is None else format(bound, "g")


def _flag(o: SimOption, v: Any) -> bool:
    if not isinstance(v, bool):
        raise TypeError(v)
    return v


def _int(o: SimOption, v: Any) -> int | None:
    if v is None and o.default is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, str)):
        raise TypeError(v)
    number = int(v, 0) if isinstance(v, str) else v
    o._bounded(number)
    return number


def _number(o: SimOption, v: Any) -> float:
    if isinstance(v, bool):
        raise TypeError(v)
    return o._bounded(float(v))


def _numbers(o: SimOption, v: Any) -> tuple[float, ...]:
    items = v.split(",") if isinstance(v, str) else list(v)
    if not o.count[0] <= len(items) <= o.count[1] or any(isinstance(x, bool) for x in items):
        raise ValueError(v)
    return tuple(o._bounded(float(x)) for x in items)


def _steps(o: SimOption, v: Any) -> tuple[tuple[str, float], ...]:
    items = v.split(",") if isinstance(v, str) else list(v)
    if not o.count[0] <= len(items) <= o.count[1]:
        raise ValueError(v)
    steps = []
    for item in items:
        choice, seconds = item.split(":") if isinstance(item, str) else item
        if not isinstance(choice, str) or choice.strip() not in o.choices or \
                isinstance(seconds, bool):
            raise ValueError(item)
        steps.append((choice.strip(), o._bounded(float(seconds))))
    return tuple(steps)


def _joints(o: SimOption, v: Any) -> tuple[str, ...]:
    names = (v,) if isinstance(v, str) else tuple(v)
    if not all(isinstance(n, str) for n in names):
        raise TypeError(v)
    return names


def _text(o: SimOption, v: Any) -> str:
    if not isinstance(v, str):
        raise TypeError(v)
    return v


_CONVERT: dict[str, Callable[[SimOption, Any], Any]] = {
    "flag": _flag, "text": _text, "int": _int, "number": _number, "numbers": _numbers,
    "steps": _steps, "joints": _joints}
_TAKES = {"flag": "true or false", "text": "a text", "int": "an integer (106 or 0x6A)",
          "number": "a number", "numbers": "comma-separated numbers",
          "steps": "comma-separated CHOICE:SECONDS steps",
          "joints": "joint names"}


@dataclass(frozen=True)
class Permission:
    """What ``config restore --allow NAME`` permits, declared by the family whose drivers ask
    for it (an entry's ``needs`` or ``opt_in``)."""

    name: str
    why: str = ""  # why a restore asks for it; "" for a safety setting, written when named
    given: str = ""  # what the restore then does, for the confirmation
    hint: str = ""  # the way on when it is missing


@dataclass(frozen=True)
class Family:
    name: str
    driver: str  # "module:Class" of its driver (a deltoctl.core.driver.Driver)
    plugins: tuple[str, ...] = ()  # ros2_control plugins that imply this family on import
    schemes: tuple[str, ...] = ()  # target URL schemes its buses use; () = no transport
    address_range: tuple[int, int] | None = None  # valid part addresses, inclusive
    address_param: str | None = None  # a plugin param that carries a part's address
    address_kind: str = "address"
    address_format: str = "d"  # how an address is shown ("#04x" for I2C)
    address_by_position: bool = False  # a joint without an address is its block's N-th (1-based)
    # a third-party block names its device by params: (host param, port param, default port)
    endpoint_params: tuple[str, str, int] | None = None
    capabilities: frozenset[str] = frozenset()
    emulator: str | None = None  # "module:function", a core.emulator_contract.Emulator
    serve_options: tuple[SimOption, ...] = ()  # the `sim serve` faults and settings it takes
    permissions: tuple[Permission, ...] = ()  # what `config restore --allow` names for it
    # how a table (fleet list) shows a block's identify report: (key, template), in order,
    # e.g. ("reported_model", "{}"), ("firmware", "fw {}"), ("servos", "({} servos)")
    identity_fields: tuple[tuple[str, str], ...] = ()
    summary: str = ""
    refused_hint: str = ""  # what to do when its TCP target refuses the connection
    register_items: str | None = None  # "module:function" → the register names it takes
    # "module:function" → {item: (low, high, permission)}: the documented range of each
    # configuration item, and the --allow `config restore` needs to write a safety setting
    config_rules: str | None = None
    # a plugin param that, "true", makes the plugin simulate its device (Bioscara's
    # use_mock_hardware): such a block runs on the family's emulator without --sim
    mock_param: str | None = None
    # "module:function" of its codec naming a frame in the -vv trace: bytes → "GET_DATA" | None
    frame_names: str | None = None
    # "module:function" (profile, block) → None: reads a block written for one of its plugins
    # (their own params and tags) into deltoctl's model when a URDF is loaded
    import_block: str | None = None
    # "module:function" (profile, block) → the names of the block's joints whose device runs
    # a homing routine of its own (the driver's ``home``), as its configuration says; a joint
    # with a ``home`` command interface has one whatever this says
    homing_joints: str | None = None
    # "module:function" () → its deltoctl.servo.scan.Probe's: how `deltoctl scan` finds its
    # devices on a serial link at an unknown rate and protocol
    scan: str | None = None
    # "module:function" () → its deltoctl.servo.addressing.Addressing: how `deltoctl setup`
    # gives its servos the profile's IDs and rates (what each joint wants, and the writes)
    setup: str | None = None
    # "module:function" (url, wait, every) → a `deltoctl scan` result: how it finds its devices
    # on a link of one of its schemes (a CAN bus), as deltoctl.app.scan.scan reports them
    link_scan: str | None = None
    # "module:function" () → its deltoctl.core.link_setup.LinkAddressing: how `deltoctl setup`
    # gives its parts on a link of one of its schemes (CANopen drives: LSS) the profile's
    # addresses and rates
    link_setup: str | None = None

    def __post_init__(self) -> None:
        unknown = self.capabilities - CAPABILITIES.keys()
        if unknown:  # a third party's typo would otherwise hide a verb without a word
            known = ", ".join(sorted(CAPABILITIES))
            raise ValueError(f"family {self.name!r}: unknown capabilities "
                             f"{', '.join(sorted(unknown))} (known: {known})")
        names = [o.name for o in self.serve_options]
        if len(set(names)) != len(names):
            raise ValueError(f"family {self.name!r}: a sim option is declared twice")

    def driver_class(self) -> type:
        """Its driver class, checked on first use: a capability without its method is one
        clear error, not an AttributeError in the middle of a verb."""
        cls = _load(self.driver)
        missing = unimplemented(self, cls)
        if missing:
            raise DeltoctlError(f"family {self.name!r}: {missing}",
                                hint="the family's package declares what its driver lacks: "
                                     "report it to its authors")
        return cls

    def emulator_function(self) -> Emulator | None:
        return _load(self.emulator) if self.emulator else None

    def frame_namer(self) -> Callable[[bytes], str | None] | None:
        return _load(self.frame_names) if self.frame_names else None

    def register_names(self) -> list[str]:
        """The register item names its ``register`` verbs take (completion)."""
        return list(_load(self.register_items)()) if self.register_items else []

    def config_rule_table(self) -> dict[str, tuple[int | None, int | None, str | None]]:
        return dict(_load(self.config_rules)()) if self.config_rules else {}

    def joints_with_homing(self, profile: Any, hw: Any) -> set[str]:
        """The joints of block ``hw`` that its devices home by a routine of their own."""
        return set(_load(self.homing_joints)(profile, hw)) if self.homing_joints else set()

    def scan_probes(self) -> list[Any]:
        return list(_load(self.scan)()) if self.scan else []

    def addressing(self) -> Any:
        return _load(self.setup)() if self.setup else None

    def link_addressing(self) -> Any:
        return _load(self.link_setup)() if self.link_setup else None

    def link_scanner(self, scheme: str) -> Callable[..., dict[str, Any]] | None:
        """Its scan of a link of this scheme, if it has one."""
        return _load(self.link_scan) if self.link_scan and scheme in self.schemes else None

    def show_address(self, address: int) -> str:
        return format(address, self.address_format)

    def is_mock(self, params: dict[str, str]) -> bool:
        """Whether a block with these params asks for the plugin's own mock mode."""
        return self.mock_param is not None and params.get(self.mock_param) in ("true", "True")


def unimplemented(family: Family, cls: type) -> str:
    """What the driver class lacks of the capabilities its family declares ("" when it has
    everything): each capability's methods must be its own, not the base class's refusal."""
    from deltoctl.core.driver import Driver

    needs = [(capability, method) for capability in sorted(family.capabilities)
             for method in CAPABILITIES[capability]]
    if family.homing_joints:  # it says which joints home by a routine: the driver runs it
        needs.append(("homing_joints", "home"))
    missing = [f"{capability} needs {method}()" for capability, method in needs
               if getattr(cls, method, None) is None
               or getattr(cls, method) is getattr(Driver, method, None)]
    if not missing:
        return ""
    return (f"its driver {cls.__name__} declares capabilities it does not implement: "
            f"{'; '.join(missing)}")


def _load(ref: str) -> Any:
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


_families: dict[str, Family] | None = None
_added: dict[str, Family] = {}


def register(family: Family) -> None:
    """Add a family at run time (tests, or a program embedding deltoctl); its driver is
    checked now against the capabilities it declares (ValueError)."""
    missing = unimplemented(family, _load(family.driver))
    if missing:
        raise ValueError(f"family {family.name!r}: {missing}")
    _added[family.name] = family
    if _families is not None:
        _families[family.name] = family


def unregister(name: str) -> None:
    _added.pop(name, None)
    if _families is not None:
        _families.pop(name, None)


def families() -> dict[str, Family]:
    """Every family: the entry points' (read once a process), then those registered."""
    global _families
    if _families is None:
        found: dict[str, Family] = {}
        for name, ref in entry_points.declared(GROUP):
            try:
                family = _load(ref)
            except Exception as exc:  # a broken third-party package must not stop the tool
                import sys

                print(f"deltoctl: warning: family {name!r} ({ref}) did not load: "
                      f"{exc}", file=sys.stderr)
                continue
            if isinstance(family, Family):
                found[family.name] = family
        _families = {**found, **_added}
    return _families


def get(name: str | None) -> Family | None:
    return families().get(name or "")


def for_plugin(plugin: str) -> str | None:
    return next((f.name for f in families().values() if plugin in f.plugins), None)


# families in packages of their own, only to say which package to install when a profile
# needs one this computer lacks: package → (family, its plugins' prefix, its URL schemes)
PACKAGES = {"deltoctl-canopen": ("canopen", "canopen_ros2_control/", ("can",))}


def install_hint(family: str | None = None, plugin: str = "", scheme: str = "") -> str:
    """``; pip install deltoctl-canopen provides it`` when a known package provides the
    family, the plugin or the URL scheme (not installed here), else ``""``."""
    for package, (name, prefix, schemes) in PACKAGES.items():
        if (family == name or (plugin and plugin.startswith(prefix))
                or scheme in schemes) and name not in families():
            return (f"; the {name} family (plugin {prefix}…) comes with the package {package}: "
                    f"pip install {package} (its source: plugins/{package})")
    return ""


def of_block(family_name: str | None, plugin: str) -> Family | None:
    """A block's family: the one it names (or its profile names), else its plugin's."""
    return get(family_name or for_plugin(plugin))


def homing_joints(profile: Any, hw: Any) -> set[str]:
    """The joints of block ``hw`` whose family says its devices home them by a routine of
    their own (its descriptor's ``homing_joints``)."""
    family = of_block(profile.family_of(hw), hw.plugin)
    return family.joints_with_homing(profile, hw) if family is not None else set()


# -- what the families declare, merged ------------------------------------------------------

def sim_options(names: Sequence[str] | None = None) -> dict[str, SimOption]:
    """The `sim serve` options of every family (or of those ``names``), by option name; an
    option several families declare (``missing``, ``stall``) is one, the first family's
    declaration; one declared again of another kind is left out with a warning."""
    merged: dict[str, SimOption] = {}
    for family in families().values():
        if names is not None and family.name not in names:
            continue
        for option in family.serve_options:
            first = merged.setdefault(option.name, option)
            if first.kind != option.kind:
                _warn(f"family {family.name!r}: sim option {option.flag} is another family's "
                      f"{first.kind} option: left out")
    return merged


def permissions() -> dict[str, Permission]:
    """Every ``--allow`` name a family declares, with why and the way on."""
    found: dict[str, Permission] = {}
    for family in families().values():
        for permission in family.permissions:
            found.setdefault(permission.name, permission)
    return found


def _warn(message: str) -> None:
    import sys

    print(f"deltoctl: warning: {message}", file=sys.stderr)


# -- transports, by URL scheme --------------------------------------------------------------

_transport_refs: dict[str, str] | None = None
_added_transports: dict[str, str] = {}
_loaded_transports: dict[str, Transport] = {}


def register_transport(scheme: str, ref: str) -> None:
    """Add a transport at run time: ``scheme`` → ``"module:attr"`` of its ``Transport``."""
    _added_transports[scheme] = ref
    _loaded_transports.pop(scheme, None)
    if _transport_refs is not None:
        _transport_refs[scheme] = ref


def unregister_transport(scheme: str) -> None:
    _added_transports.pop(scheme, None)
    _loaded_transports.pop(scheme, None)
    if _transport_refs is not None:
        _transport_refs.pop(scheme, None)


def transport_refs() -> dict[str, str]:
    """scheme → "module:attr": the built-in transports, the entry points' (read once a
    process), then those registered. Nothing is imported."""
    global _transport_refs
    if _transport_refs is None:
        from deltoctl.transport import BUILTIN

        found = dict(BUILTIN)
        found.update(entry_points.declared(TRANSPORTS))
        _transport_refs = {**found, **_added_transports}
    return _transport_refs


def transport(scheme: str) -> Transport:
    """The transport of a URL scheme, its module imported now; an unknown scheme is one
    InvalidInput naming the known ones."""
    loaded = _loaded_transports.get(scheme)
    if loaded is not None:
        return loaded
    refs = transport_refs()
    if scheme not in refs:
        raise InvalidInput(f"unknown scheme {scheme!r} (known: {', '.join(refs)})",
                           hint="use " + ", ".join(_examples()))
    from deltoctl.transport import Transport

    try:
        found = _load(refs[scheme])
    except Exception as exc:  # a broken third-party package: one clear error
        raise DeltoctlError(f"transport {scheme!r} ({refs[scheme]}) did not load: "
                            f"{type(exc).__name__}: {exc}") from None
    if not isinstance(found, Transport) or found.scheme != scheme:
        raise DeltoctlError(f"transport {scheme!r} ({refs[scheme]}) is not a deltoctl "
                            f"Transport of scheme {scheme!r}")
    _loaded_transports[scheme] = found
    return found


def _examples() -> list[str]:
    """How each transport's URL looks, for a message (the built-in ones: imported anyway)."""
    examples = []
    for scheme in transport_refs():
        try:
            examples.append(transport(scheme).example)
        except DeltoctlError:
            continue
    return examples


def transports() -> dict[str, Transport]:
    """Every transport that loads, by scheme (imports them all: doctor without a target)."""
    found = {}
    for scheme in transport_refs():
        try:
            found[scheme] = transport(scheme)
        except DeltoctlError as exc:
            _warn(exc.message)
    return found


def scheme_of(url: str) -> str:
    """A URL's scheme: ``tcp`` of ``tcp://…``, or that of a transport whose URLs have no
    authority (``usb:0403:6014``)."""
    if "://" in url:
        return url.partition("://")[0]
    head, colon, _ = url.partition(":")
    return head if colon and head in transport_refs() else ""


def transport_of(url: str) -> Transport:
    """The transport a target URL names by its scheme."""
    scheme = scheme_of(url)
    if not scheme:
        raise InvalidInput(f"{url!r} is not a target URL (no scheme)",
                           hint="use " + ", ".join(_examples()))
    try:
        return transport(scheme)
    except InvalidInput as exc:
        raise InvalidInput(f"{url!r}: {exc.message}", hint=exc.hint) from None


def trace_label(url: str) -> Callable[[str, int | None], str] | None:
    """How the transport of ``url`` labels its packets in the trace; None when it labels
    them by the URL, or the URL is bad (the driver says what is wrong with it)."""
    try:
        return transport_of(url).trace_label
    except DeltoctlError:
        return None


def open_link(url: str, links: Any = None, **options: Any) -> Any:
    """The open link to ``url``, by its scheme's transport; a transport whose links are
    shared (an I2C bus: several blocks' devices on it) is opened once per System's
    ``links``."""
    chosen = transport_of(url)
    if chosen.shared and links is not None:
        return links.shared(url, lambda: chosen.open(url, **options))
    return chosen.open(url, **options)
