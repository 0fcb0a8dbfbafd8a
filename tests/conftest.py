from __future__ import annotations

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


needs_samples = pytest.mark.skipif(not SAMPLES.is_dir(), reason="../shared/data is not present")


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path_factory.mktemp("cache")))
