"""The bring-up scripts in examples/ run start to finish against their simulated devices."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO

DELTOCTL = Path(sys.executable).parent / "deltoctl"


@pytest.mark.skipif(not DELTOCTL.exists(), reason="the deltoctl script is not installed")
@pytest.mark.parametrize("script", ["bringup.sh", "bringup-bioscara.sh", "bringup-mh5.sh"])
def test_bringup_script(script, tmp_path):
    env = {**os.environ, "DELTOCTL": str(DELTOCTL), "OUT": str(tmp_path)}
    result = subprocess.run(["bash", str(REPO / "examples" / script)], env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert list(tmp_path.glob("*.mcap"))
