"""A starting pytest suite for a robot (``deltoctl profile tests``): identify, detect, the
configuration against a golden snapshot, link quality and homing, for what the profile's
families can do. The golden snapshot is taken of the simulators, which the suite passes on as
written; the same file runs on the robot with ``--deltoctl-target`` (deltoctl.testing).

The test file is a template (templates/suite_test.py.j2); whatever comes from the profile
goes into it as a Python literal (``repr``) or reduced to safe characters, so a profile's
names cannot put code into the file."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from deltoctl.errors import InvalidInput

if TYPE_CHECKING:
    from deltoctl.app.robot import Robot
    from deltoctl.profile.model import Profile

GOLDEN_DIR = "golden"


@dataclass(frozen=True)
class Suite:
    """What was written: the test file, the golden snapshot (None when no block reports its
    configuration) and the tests' names."""

    profile: str
    test_file: Path
    golden: Path | None
    tests: list[str]

    def data(self) -> dict[str, Any]:
        return {"profile": self.profile, "test_file": str(self.test_file),
                "golden": str(self.golden) if self.golden else None, "tests": self.tests}


def slug(name: str) -> str:
    """A profile's name as a part of a file or module name."""
    return re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_").lower() or "robot"


def _shown(text: str) -> str:
    """A name as the test file's docstring shows it: safe characters only."""
    return re.sub(r"[^A-Za-z0-9_.+-]+", "_", text)


def _profile_literal(spec: str, prof: Profile, output: Path) -> str:
    """How the test file names the profile: a catalog name, or the file relative to the
    test file's folder."""
    from deltoctl.profile.catalog import catalog_names

    if spec in catalog_names():
        return repr(spec)
    relative = os.path.relpath(Path(spec).resolve(), output.resolve())
    return f"str(Path(__file__).parent / {relative!r})"


def _able(robot: Robot, capability: str) -> list[str]:
    return [m.name for m in robot.system.able(capability)]


def write_suite(spec: str, output: Path, force: bool = False) -> Suite:
    """Write the suite of profile ``spec`` into the folder ``output`` (made if missing): the
    test file and, where blocks report their configuration, ``golden/<profile>.config.yaml``
    taken of the simulators. An existing file is left alone unless ``force``."""
    from deltoctl.app import config
    from deltoctl.app.report import limits_of
    from deltoctl.app.robot import load, open_robot
    from deltoctl.profile.catalog import catalog_names

    prof = load(spec)
    name = slug(prof.name)
    test_file = output / f"test_{name}.py"
    golden = output / GOLDEN_DIR / f"{name}.config.yaml"
    with open_robot(prof, sim=True) as robot:
        snapshot = config.snapshot(robot.system)[0] if _able(robot, "config") else None
        context = {
            "name": _shown(prof.name),
            "test_file": test_file.name,
            "profile": _profile_literal(spec, prof, output),
            "option": _shown(spec) if spec in catalog_names() else "PROFILE",
            "golden_file": f"{GOLDEN_DIR}/{golden.name}",
            "identify": repr(_able(robot, "identify")),
            "detect": bool(_able(robot, "detect")),
            "golden": repr(golden.name) if snapshot else None,
            "golden_dir": repr(GOLDEN_DIR),
            "home": any(m.hw.joints for m in robot.system.able("home")),
            "error_rate": limits_of(robot)["error_rate_perc"],
        }
    files = {test_file: _render(context)}
    if snapshot is not None:
        files[golden] = config.dump_yaml(snapshot)
    existing = [str(p) for p in files if p.exists()]
    if existing and not force:
        raise InvalidInput(f"{', '.join(existing)} exists: pass --force to overwrite")
    try:
        for path, text in files.items():
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InvalidInput(f"cannot write {exc.filename}: {exc.strerror}") from None
    tests = re.findall(r"^def (test_\w+)", files[test_file], re.MULTILINE)
    return Suite(prof.name, test_file, golden if snapshot else None, tests)


def _render(context: dict[str, Any]) -> str:
    import jinja2

    env = jinja2.Environment(loader=jinja2.PackageLoader("deltoctl.app", "templates"),
                             autoescape=False, trim_blocks=True, lstrip_blocks=True,
                             keep_trailing_newline=True, undefined=jinja2.StrictUndefined)
    return env.get_template("suite_test.py.j2").render(**context)
