"""Every bad input: one line naming file:line and the element, a non-zero exit, no traceback."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from netlistdyn.cli import main

HEAD = "error test\n"

BAD_NETLISTS = {
    # name: (netlist body, line number, fragments the message must contain)
    "voltage loop": ("V1 a 0 1\nV2 a 0 2\nR1 a 0 1\n", 3, ["V2", "loop of voltage sources", "V1"]),
    "shorted source": ("V1 a a 1\nR1 a 0 1\n", 2, ["V1", "short-circuited"]),
    "current cutset": ("I1 0 a 1\nI2 a b 1\nR1 b 0 1\n", 2, ["cutset of current sources", "I1", "I2"]),
    "zero value": ("V1 a 0 1\nR1 a 0 0\n", 3, ["R1", "zero"]),
    "non-finite": ("V1 a 0 1\nR1 a 0 1e999\n", 3, ["R1", "not finite"]),
    "division by zero": ("V1 a 0 1\nR1 a 0 {1/0}\n", 3, ["R1", "division by zero"]),
    "floating node": ("V1 a 0 1\nR1 a 0 1\nC1 b c 1u\n", 4, ["C1", "no path to ground"]),
    "unknown sense source": ("V1 a 0 1\nR1 a 0 1\nF1 a 0 Vx 2\n", 4, ["F1", "'vx'", "not a voltage source"]),
    "unknown coupled inductor": ("V1 a 0 1\nL1 a 0 1\nK1 L1 L9 0.5\n", 4, ["K1", "'l9'", "not an inductor"]),
    "unknown control node": ("V1 a 0 1\nR1 a 0 1\nE1 b 0 zz 0 2\nR2 b 0 1\n", 4, ["E1", "'zz'"]),
    "unsupported element": ("V1 a 0 1\nQ1 a 0 0 qmod\n", 3, ["Q1", "bipolar", "not supported"]),
    "unknown letter": ("V1 a 0 1\nYQ1 a 0 1\n", 3, ["YQ1"]),
    "unsupported directive": ("V1 a 0 1\nR1 a 0 1\n.data foo\n", 4, ["unsupported directive .data"]),
    "missing library": ("V1 a 0 1\nR1 a 0 1\n.lib foo\n", 4, [".lib", "foo"]),
    "bare unknown name": (".param r=1k\nV1 a 0 1\nR1 a 0 rr\n", 4, ["R1", "'rr'"]),
    "unknown parameter": ("V1 a 0 1\nR1 a 0 {rx*2}\n", 3, ["R1", "unknown parameter 'rx'"]),
    "missing value": ("V1 a 0 1\nR1 a 0\n", 3, ["R1", "missing resistance"]),
    "extra field": ("V1 a 0 1\nR1 a 0 1k 2k\n", 3, ["R1", "unexpected field"]),
    "duplicate name": ("V1 a 0 1\nR1 a 0 1\nr1 a 0 2\n", 4, ["r1", "duplicate"]),
    "perfect coupling": ("V1 a 0 1\nL1 a 0 1\nL2 a 0 1\nK1 L1 L2 1\n", 5, ["K1", "ideal transformer"]),
    "unsupported source": (
        "V1 a 0 1\nR1 a 0 1\nE1 b 0 TABLE {v(a)} (0,0) (1,1)\n",
        4,
        ["E1", "TABLE", "not supported"],
    ),
    "bad continuation": ("+ R1 a 0 1\n", 2, ["continuation"]),
    "pwl odd": ("V1 a 0 PWL(0 0 1)\nR1 a 0 1\n", 2, ["V1", "PWL"]),
}


def run(args: list[str]) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, args)
    return result.exit_code, result.stdout, result.stderr


@pytest.mark.parametrize("case", sorted(BAD_NETLISTS))
def test_bad_netlist_one_line_with_location(case: str, tmp_path: Path) -> None:
    body, line, fragments = BAD_NETLISTS[case]
    path = tmp_path / "bad.cir"
    path.write_text(HEAD + body)
    code, out, err = run(["analyze", str(path)])
    assert code == 1, err
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"{path}:{line}: "), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert "Traceback" not in err


def test_negative_value_is_a_warning(tmp_path: Path) -> None:
    path = tmp_path / "neg.cir"
    path.write_text(HEAD + "V1 a 0 1\nR1 a b 1\nC1 b 0 -1u\n")
    code, out, err = run(["analyze", str(path)])
    assert code == 0
    assert f"{path}:4: warning: C1 has a negative value" in err
    assert "unstable" in out  # a negative capacitor behind a resistor grows


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--output", "v(nowhere)"], "no node 'nowhere'"),
        (["--output", "i(R9)"], "no element 'R9'"),
        (["--output", "x"], "expected v(node)"),
        (["--param", "R1"], "expected NAME=VALUE"),
        (["--param", "Rz=1"], "no .param rz"),
        (["--format", "xml"], "Invalid value"),
    ],
)
def test_bad_command_line_exit_2(args: list[str], fragment: str, netlists_dir: Path) -> None:
    code, _out, err = run(["analyze", str(netlists_dir / "circuit1.cir"), *args])
    assert code == 2
    assert fragment in err
    assert "Traceback" not in err


def test_missing_file_exit_2(tmp_path: Path) -> None:
    code, _, err = run(["analyze", str(tmp_path / "none.cir")])
    assert code == 2 and "does not exist" in err


def test_failed_run_leaves_no_output_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.cir"
    bad.write_text(HEAD + "V1 a 0 1\nV2 a 0 2\n")
    target = tmp_path / "report.json"
    code, _, _ = run(["analyze", str(bad), "--format", "json", "-o", str(target)])
    assert code == 1
    assert not target.exists()
    assert list(tmp_path.iterdir()) == [bad]


def test_output_file_written(tmp_path: Path, netlists_dir: Path) -> None:
    target = tmp_path / "report.json"
    code, out, _ = run(["analyze", str(netlists_dir / "circuit1.cir"), "--format", "json", "-o", str(target)])
    assert code == 0 and out == ""
    import json

    doc = json.loads(target.read_text())
    assert doc["states"] == ["q(C1)", "i(L1)"]
    assert doc["A"] == [[-2000.0, -1.0], [1.0, 0.0]]
    assert len(doc["eigenvalues"]) == 2
    assert "D1" not in doc
