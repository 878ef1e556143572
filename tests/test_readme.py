"""The README's example transcripts are what the commands print.

Each ``$ netlistdyn ...`` block of the README is run (from the repository
root, as the README's commands are) and its lines must appear in the
output in order; a ``...`` line stands for any number of lines. Words must
match exactly. Numbers are compared as printed figures:

- an error estimate or error figure below :data:`ROUNDING_LEVEL` measures
  rounding, whose size depends on the order of floating-point operations
  (the BLAS, the CPU): it must be within a factor :data:`ROUNDING_FACTOR`;
- any other number must agree to :data:`PRINTED_RTOL`, the resolution of
  the 3–6 significant digits the reports print (the last digit may fall on
  either side of a rounding boundary).
"""

from __future__ import annotations

import re
import shlex
import shutil

import pytest
from click.testing import CliRunner

from netlistdyn.cli import main

from .conftest import ROOT

#: Relative agreement of printed figures (one unit in the 3rd significant digit at worst).
PRINTED_RTOL = 1e-2
#: Figures below this are rounding-error measures (relative errors, error bars).
ROUNDING_LEVEL = 1e-12
#: A rounding-error measure may differ by this factor between machines.
ROUNDING_FACTOR = 10.0

_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def _transcripts() -> list[tuple[str, list[str]]]:
    """(command, expected lines) of each ``$ netlistdyn`` block in the README."""
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    found = []
    for k, line in enumerate(lines):
        if line.startswith("$ netlistdyn ") and lines[k - 1].strip() == "```":
            end = next(j for j in range(k + 1, len(lines)) if lines[j].strip() == "```")
            found.append((line[2:], lines[k + 1 : end]))
    return found


def _same_token(expected: str, actual: str) -> bool:
    if expected == actual:
        return True
    if not (_NUMBER.match(expected) and _NUMBER.match(actual)):
        return False
    e, a = float(expected), float(actual)
    if abs(e) < ROUNDING_LEVEL and abs(a) < ROUNDING_LEVEL:
        return (e == 0) == (a == 0) and (e == 0 or 1 / ROUNDING_FACTOR <= abs(a / e) <= ROUNDING_FACTOR)
    return abs(a - e) <= PRINTED_RTOL * max(abs(e), abs(a))


def _same_line(expected: str, actual: str) -> bool:
    e, a = expected.split(), actual.split()
    return len(e) == len(a) and all(_same_token(x, y) for x, y in zip(e, a, strict=True))


def _follows(expected: list[str], output: list[str]) -> str | None:
    """None when the expected lines appear in order (``...``: any lines); else the first missing one.

    A transcript may start anywhere (the README leaves out the title lines).
    """
    position, free = 0, True
    for line in expected:
        if line.strip() == "...":
            free = True
            continue
        candidates = range(position, len(output)) if free else range(position, min(position + 1, len(output)))
        hit = next((j for j in candidates if _same_line(line, output[j])), None)
        if hit is None:
            return line
        position, free = hit + 1, False
    return None


TRANSCRIPTS = _transcripts()


def test_the_readme_has_its_example_transcripts() -> None:
    commands = [c for c, _ in TRANSCRIPTS]
    assert "netlistdyn analyze netlists/circuit1.cir" in commands


@pytest.mark.parametrize("command, expected", TRANSCRIPTS, ids=[c for c, _ in TRANSCRIPTS])
def test_transcript_is_what_the_command_prints(
    command: str, expected: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    args = shlex.split(command)[1:]
    if args[0] in ("validate", "bench") and shutil.which("ngspice") is None:
        pytest.skip("ngspice is not installed")
    monkeypatch.chdir(ROOT)
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    missing = _follows(expected, result.output.splitlines())
    assert missing is None, (
        f"README line not printed by `{command}`:\n{missing}\n--- printed:\n{result.output}"
    )
