"""The example transcripts of the README and of the documentation are what the commands print.

Each ``$ netlistdyn ...`` block of the README and of the documentation's own
pages (:data:`DOC_PAGES`) is run (from the repository root, as their commands
are) and its lines must appear in the output in order; a ``...`` line stands
for any number of lines. Words must match exactly. Numbers are compared as printed figures:

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
from pathlib import Path

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


#: The documentation's pages in its sections' folders (the guide, the language, the examples, the
#: campaigns); pages directly in ``docs/`` are topic pages whose transcripts their authors check.
DOC_PAGES = sorted((ROOT / "docs").glob("*/**/*.md"))


def _transcripts_of(page: Path) -> list[tuple[str, list[str]]]:
    """(command, expected lines) of each ``$ netlistdyn`` block of one Markdown page."""
    lines = page.read_text(encoding="utf-8").splitlines()
    found = []
    for k, line in enumerate(lines):
        if line.startswith("$ netlistdyn ") and k > 0 and lines[k - 1].strip() == "```":
            end = next(j for j in range(k + 1, len(lines)) if lines[j].strip() == "```")
            found.append((line[2:], lines[k + 1 : end]))
    return found


def _transcripts() -> list[tuple[str, list[str]]]:
    """(command, expected lines) of each ``$ netlistdyn`` block in the README."""
    return _transcripts_of(ROOT / "README.md")


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
#: (page, command, expected lines) of the README and of every documentation page.
ALL_TRANSCRIPTS = [
    (page.relative_to(ROOT).as_posix(), command, expected)
    for page in [ROOT / "README.md", *DOC_PAGES]
    for command, expected in _transcripts_of(page)
]


def test_the_readme_has_its_example_transcripts() -> None:
    commands = [c for c, _ in TRANSCRIPTS]
    assert "netlistdyn analyze netlists/circuit1.cir" in commands


def test_the_documentation_has_transcripts_too() -> None:
    """The transcripts moved out of the README into the guide are still checked."""
    pages = {page for page, _, _ in ALL_TRANSCRIPTS}
    assert "docs/guide/validate.md" in pages
    assert "docs/guide/analyze.md" in pages


@pytest.mark.parametrize(
    "page, command, expected", ALL_TRANSCRIPTS, ids=[f"{p}: {c}" for p, c, _ in ALL_TRANSCRIPTS]
)
def test_transcript_is_what_the_command_prints(
    page: str, command: str, expected: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    args = shlex.split(command)[1:]
    if args[0] in ("validate", "bench") and shutil.which("ngspice") is None:
        pytest.skip("ngspice is not installed")
    monkeypatch.chdir(ROOT)
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    missing = _follows(expected, result.output.splitlines())
    assert missing is None, (
        f"{page} line not printed by `{command}`:\n{missing}\n--- printed:\n{result.output}"
    )
