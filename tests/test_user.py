"""The everyday edges of issue #16: ``python -m``, the Python API, reprs, options, schemas."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from .conftest import NETLISTS, ROOT


def _python_m(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", *args], capture_output=True, text=True, env=env, timeout=120, check=False
    )


def test_python_m_netlistdyn_runs_the_cli() -> None:
    done = _python_m("netlistdyn", "analyze", str(NETLISTS / "circuit1.cir"), "--eig", "none")
    assert done.returncode == 0, done.stderr
    assert "q(C1)" in done.stdout


def test_python_m_cli_knows_every_command(tmp_path: Path) -> None:
    done = _python_m("netlistdyn.cli", "connect", "--help")
    assert done.returncode == 0, done.stderr
    assert "series" in done.stdout
