"""Killing a run that writes files never leaves a partial target (nor, for SIGTERM, a temporary).

``analyze --format json -o`` and ``--save`` on a ladder of a few thousand states are started in a
child process and sent SIGTERM or SIGKILL at random moments spread over the run (start-up,
compilation, each write). Afterwards each target is either absent or complete: byte-identical
to the output of an uninterrupted run. After SIGTERM no ``.netlistdyn-*.tmp`` file may remain;
after SIGKILL one may (nothing can run), but never a partial target. (A SIGTERM that lands
during a write is tested deterministically in test_robust.py.)
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SECTIONS = 1000
RUNS_PER_SIGNAL = 4


def ladder(path: Path) -> None:
    lines = ["RLC ladder for the kill test", "V1 n0 0 PULSE(0 1 0 1u 1u 1m 2m)"]
    for k in range(1, SECTIONS + 1):
        lines += [f"R{k} n{k - 1} m{k} 1", f"L{k} m{k} n{k} 1m", f"C{k} n{k} 0 1u"]
    path.write_text("\n".join(lines) + "\n")


def command(folder: Path) -> list[str]:
    return [
        sys.executable,
        "-m",
        "netlistdyn",
        "analyze",
        "ladder.cir",
        "--output",
        f"v(n{SECTIONS})",
        "--eig",
        "none",
        "--format",
        "json",
        "-o",
        "out.json",
        "--save",
        "model.npz",
    ]


def start(folder: Path) -> subprocess.Popen[bytes]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(command(folder), cwd=folder, env=env, stderr=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, bytes], float]:
    folder = tmp_path_factory.mktemp("kill_reference")
    ladder(folder / "ladder.cir")
    begin = time.perf_counter()
    proc = start(folder)
    assert proc.wait(timeout=300) == 0
    seconds = time.perf_counter() - begin
    return {name: (folder / name).read_bytes() for name in ("out.json", "model.npz")}, seconds


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_killed_run_leaves_no_partial_file(
    signum: int, reference: tuple[dict[str, bytes], float], tmp_path: Path
) -> None:
    expected, seconds = reference
    rng = random.Random(20261122 + signum)
    killed = 0
    for run in range(RUNS_PER_SIGNAL):
        folder = tmp_path / f"run{run}"
        folder.mkdir()
        ladder(folder / "ladder.cir")
        proc = start(folder)
        time.sleep(rng.uniform(0.2, 1.1) * seconds)
        proc.send_signal(signum)
        code = proc.wait(timeout=300)
        killed += code == -signum
        names = {p.name for p in folder.iterdir()} - {"ladder.cir"}
        for name, content in expected.items():
            if name in names:
                assert (folder / name).read_bytes() == content, f"partial {name} after {signum}"
        leftovers = {n for n in names if n not in expected}
        if signum == signal.SIGTERM:
            assert leftovers == set(), leftovers
            assert code in (0, -signal.SIGTERM)
        else:
            assert all(".netlistdyn-" in n and n.endswith(".tmp") for n in leftovers), leftovers
    assert killed >= 1  # the signal landed before the end at least once (the times are spread)
