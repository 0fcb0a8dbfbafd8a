"""The device families deltoctl can drive, found through the ``deltoctl.families`` entry-point
group (the built-in ones are registered in ``pyproject.toml``; a third party adds one by
installing a package that names its descriptor there).

A descriptor is data and strings: reading the registry imports each family's small
``__init__`` only; its driver and emulator modules are imported when a block of that family is
opened (``Family.driver_class()``, ``Family.emulator()``), the way python-can loads an
interface only when a bus of that kind is opened.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

GROUP = "deltoctl.families"

# what a verb may ask of a driver, beyond the lifecycle and read/write
CAPABILITIES = frozenset({
    "identify", "detect", "home", "jog", "calibrate_ft", "gpio", "registers", "torque",
    "reboot", "config", "calibrate_imu",
})


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
    emulator: str | None = None  # "module:function" serving a simulated device (sim/serve.py)
    serve_options: tuple[str, ...] = ()  # the `sim serve` faults and settings it takes
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

    def __post_init__(self) -> None:
        unknown = self.capabilities - CAPABILITIES
        if unknown:  # a third party's typo would otherwise hide a verb without a word
            known = ", ".join(sorted(CAPABILITIES))
            raise ValueError(f"family {self.name!r}: unknown capabilities "
                             f"{', '.join(sorted(unknown))} (known: {known})")

    def driver_class(self) -> type:
        return _load(self.driver)

    def emulator_function(self) -> Callable[..., Any] | None:
        return _load(self.emulator) if self.emulator else None

    def frame_namer(self) -> Callable[[bytes], str | None] | None:
        return _load(self.frame_names) if self.frame_names else None

    def register_names(self) -> list[str]:
        """The register item names its ``register`` verbs take (completion)."""
        return list(_load(self.register_items)()) if self.register_items else []

    def config_rule_table(self) -> dict[str, tuple[int | None, int | None, str | None]]:
        return dict(_load(self.config_rules)()) if self.config_rules else {}

    def show_address(self, address: int) -> str:
        return format(address, self.address_format)

    def is_mock(self, params: dict[str, str]) -> bool:
        """Whether a block with these params asks for the plugin's own mock mode."""
        return self.mock_param is not None and params.get(self.mock_param) in ("true", "True")


def _load(ref: str) -> Any:
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


_families: dict[str, Family] | None = None
_added: dict[str, Family] = {}


def register(family: Family) -> None:
    """Add a family at run time (tests, or a program embedding deltoctl)."""
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
        from importlib.metadata import entry_points

        found: dict[str, Family] = {}
        for ep in entry_points(group=GROUP):
            try:
                family = ep.load()
            except Exception as exc:  # a broken third-party package must not stop the tool
                import sys

                print(f"deltoctl: warning: family {ep.name!r} ({ep.value}) did not load: "
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


def of_block(family_name: str | None, plugin: str) -> Family | None:
    """A block's family: the one it names (or its profile names), else its plugin's."""
    return get(family_name or for_plugin(plugin))
