"""Every faulty input of tests/bad_inputs/: one line on stderr, exit 1 or 2, no traceback, no file left.

The inputs and what each must produce are in ``tests/bad_inputs/manifest.json`` (written by
``tests/bad_inputs/make_inputs.py``). Each case runs the command line in a copy of the folder;
afterwards the folder must hold exactly what it held before (no output, no temporary). A case
waiting for another helper's fix is marked xfail (non-strict) with the owner's name.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import FrameType
from typing import Any

import pytest
from click.testing import CliRunner

from netlistdyn.cli import main

HERE = Path(__file__).resolve().parent / "bad_inputs"
CASES: list[dict[str, Any]] = json.loads((HERE / "manifest.json").read_text())
#: CPU seconds a faulty input may take before it is refused (the acceptance bound).
CPU_LIMIT = 10.0
#: Wall-clock seconds before a case counts as hung (generous: the CI machine is shared).
WALL_LIMIT = 60
#: Wall-clock seconds for an isolated case (its child is killed after; the bound is 10 s of CPU).
ISOLATED_WALL_LIMIT = 15
#: Address space of a child running an isolated case (an unfixed expansion bomb stops here).
MEMORY_LIMIT = 2 << 30
ROOT = Path(__file__).resolve().parent.parent


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def run_isolated(args: list[str], cwd: Path) -> tuple[int, str, float]:
    """Run the command line in a child with a memory and time limit: (exit, stderr, CPU seconds)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("NETLISTDYN_DEBUG", None)
    start = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "netlistdyn", *args],
            cwd=cwd,
            env=env,
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=ISOLATED_WALL_LIMIT,
            preexec_fn=_limit_memory,
        )
    except subprocess.TimeoutExpired as exc:
        raise Hung(f"no answer within {WALL_LIMIT} s") from exc
    end = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (end.ru_utime - start.ru_utime) + (end.ru_stime - start.ru_stime)
    return proc.returncode, proc.stderr, cpu


class Hung(Exception):
    """The case ran past the wall-clock limit."""


def _params() -> list[Any]:
    out = []
    for case in CASES:
        marks = []
        if case.get("owner"):
            marks.append(
                pytest.mark.xfail(reason=f"waits for the {case['owner']} helper's fix", strict=False)
            )
        out.append(pytest.param(case, id=case["file"], marks=marks))
    return out


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    target = tmp_path_factory.mktemp("bad_inputs")
    for path in HERE.iterdir():
        if path.is_file() and path.name not in ("make_inputs.py", "manifest.json"):
            shutil.copy2(path, target / path.name)
    return target


@pytest.fixture
def alarm() -> Iterator[None]:
    def fire(_signum: int, _frame: FrameType | None) -> None:
        raise Hung(f"no answer within {WALL_LIMIT} s")

    old = signal.signal(signal.SIGALRM, fire)
    signal.alarm(WALL_LIMIT)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def test_manifest_is_large_and_files_exist() -> None:
    assert len(CASES) >= 150
    names = [case["file"] for case in CASES]
    assert len(set(names)) == len(names)
    for name in names:
        assert (HERE / name).is_file(), name
    assert {case["exit"] for case in CASES} <= {1, 2}


@pytest.mark.parametrize("case", _params())
def test_bad_input(case: dict[str, Any], workdir: Path, monkeypatch: pytest.MonkeyPatch, alarm: None) -> None:
    monkeypatch.chdir(workdir)
    extra = workdir / case["extra"] if "extra" in case else None
    if case.get("setup") == "fifo" and extra is not None:
        os.mkfifo(extra)
    before = sorted(os.listdir(workdir))
    args = [arg.replace("{file}", case["file"]) for arg in case["args"]]
    try:
        if case.get("isolate"):
            code, err, cpu = run_isolated(args, workdir)
        else:
            start = time.process_time()
            result = CliRunner().invoke(main, args, input="")
            cpu = time.process_time() - start
            code, err = result.exit_code, result.stderr
    finally:
        if extra is not None and extra.exists():
            extra.unlink()
    after = sorted(os.listdir(workdir))
    lines = err.strip().splitlines()
    assert "Traceback" not in err
    assert code == case["exit"], err
    assert len(lines) == 1, err
    where = case["where"].replace("{file}", case["file"])
    if case["where"].startswith("{file}:"):
        assert lines[0].startswith(where + ":"), (where, lines[0])
    else:
        assert where in lines[0], (where, lines[0])
    assert case["fragment"] in lines[0], (case["fragment"], lines[0])
    assert len(lines[0]) < 500
    assert cpu < CPU_LIMIT
    assert after == [n for n in before if n != (extra.name if extra else None)], set(after) ^ set(before)
