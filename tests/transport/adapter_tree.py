"""A computer's adapters laid out as the kernel and udev lay them out, under a root directory
(DELTOCTL_SYSFS_ROOT): the USB device and interface directories with their attributes and
driver links, /sys/class/tty, /sys/bus/usb-serial/devices, latency_timer, /dev/serial/by-id
and by-path links, /sys/class/net/canN, /sys/class/i2c-adapter. Each serial node in /dev is a
pseudo-terminal, so a port opened through a by-id link is a real port."""

from __future__ import annotations

import json
import os
import pty
import re
from dataclasses import dataclass, field
from pathlib import Path

PCI = "sys/devices/pci0000:00/0000:00:14.0/usb1"


@dataclass
class Usb:
    port: str  # 1-2: where on the hub it is plugged
    vid: str
    pid: str
    manufacturer: str
    product: str
    serial: str | None
    driver: str  # the USB interface's driver: ftdi_sio, ch341, cdc_acm, cp210x, gs_usb


@dataclass
class Tree:
    root: Path
    ptys: dict[str, int] = field(default_factory=dict)  # tty → its pseudo-terminal's master

    def close(self) -> None:
        for master in self.ptys.values():
            os.close(master)

    def _link(self, link: str, target: str) -> None:
        path = self.root / link
        path.parent.mkdir(parents=True, exist_ok=True)
        os.symlink(target, path)

    def _write(self, path: str, text: str) -> None:
        full = self.root / path
        full.parent.mkdir(parents=True, exist_ok=True)
        full.write_text(text + "\n")

    def _usb(self, usb: Usb) -> str:
        """The USB device and its interface 0; the interface's directory."""
        device = f"{PCI}/{usb.port}"
        for key, value in (("idVendor", usb.vid), ("idProduct", usb.pid),
                           ("manufacturer", usb.manufacturer), ("product", usb.product),
                           ("serial", usb.serial)):
            if value is not None:
                self._write(f"{device}/{key}", value)
        interface = f"{device}/{usb.port}:1.0"
        self._write(f"{interface}/bInterfaceNumber", "00")
        (self.root / f"sys/bus/usb/drivers/{usb.driver}").mkdir(parents=True, exist_ok=True)
        self._link(f"{interface}/driver", _up(interface, f"sys/bus/usb/drivers/{usb.driver}"))
        return interface

    def serial(self, name: str, usb: Usb, latency_ms: int | None = None,
               node: str | None = None) -> str:
        """A USB serial adapter as /dev/NAME (a pseudo-terminal, or ``node``: e.g. an
        emulator's), its by-id link (named as udev names it) and by-path link; ``latency_ms``
        for an FTDI's latency_timer. The by-id path."""
        interface = self._usb(usb)
        if name.startswith("ttyUSB"):  # a usb-serial port below the interface
            port = f"{interface}/{name}"
            serial_driver = {"ch341": "ch341-uart"}.get(usb.driver, usb.driver)
            (self.root / f"sys/bus/usb-serial/drivers/{serial_driver}").mkdir(
                parents=True, exist_ok=True)
            self._link(f"{port}/driver", _up(port, f"sys/bus/usb-serial/drivers/{serial_driver}"))
            self._link(f"sys/bus/usb-serial/devices/{name}", _up("sys/bus/usb-serial/devices",
                                                                  port))
            if latency_ms is not None:
                self._write(f"{port}/latency_timer", str(latency_ms))
        else:  # cdc_acm: the tty hangs off the interface itself
            port = interface
        tty = f"{port}/tty/{name}"
        self._write(f"{tty}/dev", "188:0")
        self._link(f"{tty}/device", _up(tty, port))
        self._link(f"sys/class/tty/{name}", _up("sys/class/tty", tty))
        self._link(f"dev/{name}", node or self._pty(name))
        vendor = re.sub(r"[^A-Za-z0-9._-]", "_", usb.manufacturer)  # as udev escapes them
        product = re.sub(r"[^A-Za-z0-9._-]", "_", usb.product)
        by_id = f"usb-{vendor}_{product}_{usb.serial or ''}-if00" + \
            ("-port0" if name.startswith("ttyUSB") else "")
        self._link(f"dev/serial/by-id/{by_id}", f"../../{name}")
        self._link(f"dev/serial/by-path/pci-0000:00:14.0-usb-0:{usb.port[2:]}:1.0"
                   + ("-port0" if name.startswith("ttyUSB") else ""), f"../../{name}")
        return str(self.root / f"dev/serial/by-id/{by_id}")

    def platform_uart(self, name: str = "ttyS0", driver: str = "serial8250",
                      device: str = "serial8250") -> None:
        """A UART that is no USB device: a PC's 8250 (no adapter), or an on-board one with a
        driver of its own (an SC16IS752 on SPI: ttySC0, sc16is7xx)."""
        parent = f"sys/devices/platform/{device}"
        port = f"{parent}/tty/{name}"
        (self.root / f"sys/bus/platform/drivers/{driver}").mkdir(parents=True, exist_ok=True)
        if not (self.root / parent / "driver").exists():
            self._link(f"{parent}/driver", _up(parent, f"sys/bus/platform/drivers/{driver}"))
        self._write(f"{port}/dev", "4:64")
        self._link(f"{port}/device", _up(port, parent))
        self._link(f"sys/class/tty/{name}", _up("sys/class/tty", port))
        self._link(f"dev/{name}", self._pty(name))

    def can(self, name: str, up: bool, usb: Usb | None = None) -> None:
        """A CAN network interface (type 280), on a USB adapter when ``usb``."""
        parent = self._usb(usb) if usb else "sys/devices/virtual"
        folder = f"{parent}/net/{name}"
        self._write(f"{folder}/type", "280")
        self._write(f"{folder}/flags", "0x41" if up else "0x0")
        self._write(f"{folder}/operstate", "up" if up else "down")
        if usb:
            self._link(f"{folder}/device", _up(folder, parent))
        self._link(f"sys/class/net/{name}", _up("sys/class/net", folder))

    def i2c(self, number: int, name: str) -> None:
        folder = f"sys/devices/platform/soc/i2c@{number}/i2c-{number}"
        self._write(f"{folder}/name", name)
        self._link(f"sys/class/i2c-adapter/i2c-{number}", _up("sys/class/i2c-adapter", folder))
        self._link(f"dev/i2c-{number}", self._pty(f"i2c-{number}"))  # a character device

    def _pty(self, name: str) -> str:
        """A pseudo-terminal that only its master holds: the slave is opened by who uses it."""
        master, slave = pty.openpty()
        path = os.ttyname(slave)
        os.close(slave)
        self.ptys[name] = master
        return path


def _up(link_dir: str, target: str) -> str:
    """The relative path from the directory holding a link to ``target`` (both under root),
    as sysfs writes its links."""
    return os.path.relpath(target, link_dir)


U2D2 = Usb("1-2", "0403", "6014", "FTDI", "USB <-> Serial Converter", "FT6Z5XYZ", "ftdi_sio")
U2D2_B = Usb("1-5", "0403", "6014", "FTDI", "USB <-> Serial Converter", "FT7ABCDE", "ftdi_sio")
CH343 = Usb("1-3", "1a86", "55d3", "QinHeng Electronics", "USB Single Serial", "5A7C121362",
            "cdc_acm")
CH340 = Usb("1-6", "1a86", "7523", "QinHeng Electronics", "USB Serial", None, "ch341")
CANDLE = Usb("1-4", "1d50", "606f", "bytewerk", "candleLight USB to CAN adapter", "0042",
             "gs_usb")


def fake_ip(folder: Path, records: list[dict]) -> Path:
    """An ``ip`` command that prints ``records`` for ``ip -details -statistics -json link show``, as
    iproute2 prints a CAN interface's details; put ``folder`` first on PATH."""
    folder.mkdir(parents=True, exist_ok=True)
    script = folder / "ip"
    script.write_text("#!/bin/sh\ncat <<'EOF'\n" + json.dumps(records) + "\nEOF\n")
    script.chmod(0o755)
    return folder


def can_record(name: str, bitrate: int, state: str = "ERROR-ACTIVE", tx: int = 0,
               rx: int = 0, restart_ms: int = 0, bus_off: int = 0) -> dict:
    """``ip -details -statistics -json link show`` of a CAN interface (iproute2's keys)."""
    return {"ifname": name, "flags": ["NOARP", "UP"], "link_type": "can",
            "linkinfo": {"info_kind": "can",
                         "info_data": {"state": state, "restart_ms": restart_ms,
                                       "berr_counter": {"tx": tx, "rx": rx},
                                       "bittiming": {"bitrate": bitrate, "sample_point": "0.875"}},
                         "info_xstats": {"restarts": 0, "bus_error": 0, "arbitration_lost": 0,
                                         "error_warning": 0, "error_passive": 0,
                                         "bus_off": bus_off}}}
