"""A light import: ``import netlistdyn`` and every ``--help`` load none of the heavy libraries.

Each check runs in a fresh interpreter (this test process has long imported everything) and looks only
at ``sys.modules``; the CPU it saves is measured by ``benchmarks/import_cost.py``, not timed here.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import netlistdyn

ROOT = Path(__file__).resolve().parent.parent

#: Modules a plain import or a help text must not load (each costs from 0.1 to 0.8 s of CPU).
HEAVY = ("scipy.linalg", "networkx", "matplotlib", "PySpice", "sympy")

_CHECK = """
import json, sys
{code}
print(json.dumps([m for m in {heavy!r} if m in sys.modules]))
"""

_HELP = """
import contextlib, io
from netlistdyn.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        main({args!r}, prog_name="netlistdyn")
    except SystemExit as stop:
        assert stop.code == 0, stop.code
"""


def loaded_heavy(code: str) -> list[str]:
    """The modules of :data:`HEAVY` that a fresh interpreter holds after running ``code``."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    script = _CHECK.format(code=code, heavy=HEAVY)
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, check=True
    )
    return json.loads(done.stdout.splitlines()[-1])


def test_import_netlistdyn_is_light() -> None:
    assert loaded_heavy("import netlistdyn") == []


@pytest.mark.parametrize(
    "args",
    [
        ["--help"],
        *[[c, "--help"] for c in ("analyze", "bench", "connect", "op", "simulate", "sweep", "validate")],
    ],
)
def test_help_is_light(args: list[str]) -> None:
    assert loaded_heavy(_HELP.format(args=args)) == []


def test_check_sees_a_heavy_import() -> None:
    # The check itself can fail: a public name used for real loads the compiler and scipy.linalg.
    assert "scipy.linalg" in loaded_heavy("import netlistdyn; netlistdyn.compile")


def test_public_names_resolve() -> None:
    for name in netlistdyn.__all__:
        assert getattr(netlistdyn, name) is not None, name
    assert set(netlistdyn.__all__) <= set(dir(netlistdyn))
    with pytest.raises(AttributeError, match="no_such_name"):
        _ = netlistdyn.no_such_name  # type: ignore[attr-defined]
