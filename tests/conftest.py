from __future__ import annotations

import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from deltoctl.cli.main import app

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared"
SAMPLES = SHARED / "data" / "urdf"


@pytest.fixture
def cli():
    """Run deltoctl in-process; returns the click Result (stdout and stderr apart)."""
    runner = CliRunner()

    def run(*args: str, **kwargs):
        return runner.invoke(app, list(args), **kwargs)

    return run


def eventually(predicate, timeout: float = 2.0) -> bool:
    """For writes without a reply: true once an emulator thread has applied them."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


needs_samples = pytest.mark.skipif(not SAMPLES.is_dir(), reason="../shared/data is not present")


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path_factory.mktemp("cache")))
