"""``validate`` checks the model against ngspice's reading of the ORIGINAL file (issue #10).

The transient comparison feeds ngspice the netlist as netlistdyn understood it,
so a parse-level misreading passes it. These tests misread a netlist on
purpose (our reader's result is altered through a monkeypatch, the file is
not) and require ``validate`` to fail through the original-file check, while
the transient comparison alone still passes.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
from click.testing import CliRunner

import netlistdyn.frontend.parser
import netlistdyn.workflows.pipelines
from netlistdyn.circuit.netlist import Kind, Netlist
from netlistdyn.cli import main
from netlistdyn.spice.ngspice import ngspice_missing, ngspice_source_name

from .conftest import NETLISTS
from .ngspice_reading import ngspice_available

pytestmark = pytest.mark.skipif(
    ngspice_missing() is not None or not ngspice_available(), reason="ngspice is not installed"
)

GLOBAL_NETLIST = """\
stage fed from a global supply node
.global vcc
Vs vcc 0 DC 2
.subckt stage in out
R1 vcc out 1k
C1 out 0 1u
R2 in out 2.2k
.ends
Vin a 0 DC 1
X1 a b stage
R3 b 0 4.7k
.tran 10u 20m
.end
"""


def _validate(path: Path) -> tuple[int, dict]:
    result = CliRunner().invoke(main, ["validate", "--format", "json", "--no-pz", str(path)])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    return result.exit_code, json.loads(result.stdout)


def _patch_reader(monkeypatch: pytest.MonkeyPatch, change) -> None:
    real = netlistdyn.frontend.parser.parse_file

    def misreading(path, overrides=None):
        netlist: Netlist = real(path, overrides)
        return replace(netlist, elements=tuple(change(e) for e in netlist.elements))

    # validate reads the netlist through the pipeline, which holds its own reference to parse_file
    monkeypatch.setattr(netlistdyn.workflows.pipelines, "parse_file", misreading)


def _transient_passes(report: dict) -> bool:
    return all(o["max_rel_error"] <= report["rtol"] for o in report["comparisons"])


def test_faithful_reading_passes() -> None:
    code, report = _validate(NETLISTS / "circuit1.cir")
    assert code == 0
    assert any("original file" in n and "agrees" in n for n in report["notes"]), report["notes"]


def test_param_override_reaches_ngspice() -> None:
    """``--param`` is applied to ngspice's reading too (alterparam), so it still agrees."""
    result = CliRunner().invoke(
        main,
        [
            "validate",
            "--format",
            "json",
            "--no-pz",
            "--param",
            "R1=100",
            "--param",
            "R2=100",
            str(NETLISTS / "circuit1.cir"),
        ],
    )
    report = json.loads(result.stdout)
    assert result.exit_code == 0, report["notes"]
    assert any("original file" in n and "agrees" in n for n in report["notes"])


def test_global_disabled_in_our_reader_fails_validate(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``.global vcc`` ignored: X1's R1 hangs from a local x1.vcc; only the new check sees it."""
    path = tmp_path / "global.cir"
    path.write_text(GLOBAL_NETLIST)

    def localise(e):
        if "." in e.name and "vcc" in e.nodes:
            prefix = e.name.rsplit(".", 1)[0].lower()
            return replace(e, nodes=tuple(f"{prefix}.vcc" if n == "vcc" else n for n in e.nodes))
        return e

    _patch_reader(monkeypatch, localise)
    code, report = _validate(path)
    assert code == 3
    assert report["original_file"]["ran"] and not report["original_file"]["passed"]
    assert _transient_passes(report), "the misread netlist itself must still match ngspice's run of it"
    assert any("DISAGREES" in n for n in report["notes"]), report["notes"]


def test_misread_value_fails_validate(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A resistor read 1 % high (think: a unit letter misread) fails validate."""
    path = tmp_path / "global.cir"
    path.write_text(GLOBAL_NETLIST.replace(".global vcc\n", "").replace("R1 vcc", "R1 a"))
    _patch_reader(monkeypatch, lambda e: replace(e, value=e.value * 1.01) if e.kind is Kind.RESISTOR else e)
    code, report = _validate(path)
    assert code == 3
    assert _transient_passes(report)
    worst = [n for n in report["notes"] if "original file" in n]
    assert worst and "DISAGREES" in worst[0]


def test_source_names_follow_ngspice() -> None:
    assert ngspice_source_name("V1") == "v1"
    assert ngspice_source_name("X1.X2.Vs") == "v.x1.x2.vs"
