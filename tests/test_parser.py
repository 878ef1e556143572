"""SPICE syntax as ngspice reads it: numbers, comments, continuations, params."""

from __future__ import annotations

import pytest

from netlistdyn.base.errors import UsageError
from netlistdyn.base.values import parse_number
from netlistdyn.circuit.expressions import ExpressionError, evaluate
from netlistdyn.circuit.netlist import Kind
from netlistdyn.circuit.waveforms import Exp, Pulse, Pwl, Sin
from netlistdyn.frontend.parser import parse_file, parse_text
from tests.conftest import NETLISTS


@pytest.mark.parametrize(
    ("token", "value"),
    [
        ("10uF", 1e-5),
        ("4.7k", 4700.0),
        ("1Meg", 1e6),
        ("1MEG", 1e6),
        ("1M", 1e-3),
        ("1m", 1e-3),
        ("2mil", 2 * 25.4e-6),
        ("1e-3", 1e-3),
        (".5", 0.5),
        ("47Ohm", 47.0),
        ("10mH", 1e-2),
        ("1F", 1e-15),
        ("3p", 3e-12),
        ("2n", 2e-9),
        ("1T", 1e12),
        ("1g", 1e9),
        ("-2.5e3m", -2.5),
        ("1e3k", 1e6),
        ("100", 100.0),
        ("5V", 5.0),
    ],
)
def test_spice_numbers(token: str, value: float) -> None:
    assert parse_number(token) == value  # exact: decimal strings are rounded once


@pytest.mark.parametrize("token", ["r1", "k", "1+2", "1.2.3x4", ""])
def test_not_numbers(token: str) -> None:
    assert parse_number(token) is None


def test_expressions() -> None:
    params = {"r": 2.0, "c": 1e-6}
    assert evaluate("1/(r*c)", params) == pytest.approx(5e5)
    # ngspice 39 (measured with ngspice -b): ** is left associative, 2**3**2 = 64
    assert evaluate("2**3**2", {}) == 64.0
    assert evaluate("-2^2", {}) == -4.0
    assert evaluate("sqrt(16)+max(1,3)", {}) == 7.0
    assert evaluate("2k*r", params) == 4000.0
    for bad in ["1/0", "foo+1", "__import__('os')", "(1", "1 2", "r.__class__"]:
        with pytest.raises(ExpressionError):
            evaluate(bad, params)


NETLIST = """My Title line R1 1 0 1k
* a comment
.param rr = 2k  cc={1u*2}
.param tau={rr*cc}
V1 IN gnd DC 5 ; inline comment
R1 in OUT {rr}
+ ; continuation carrying nothing but a comment
C1 out 0
+ {cc}
L1 out 0 {tau*1k}   $ dollar comment
.tran 1u 1m
.print tran v(out)
.end
R9 never 0 1
"""


def test_full_netlist_conventions() -> None:
    net = parse_text(NETLIST)
    assert net.title == "My Title line R1 1 0 1k"
    names = [e.name for e in net.elements]
    assert names == ["V1", "R1", "C1", "L1"]  # nothing after .end
    v1, r1, c1, l1 = net.elements
    assert v1.nodes == ("in", "0") and v1.value == 5.0
    assert r1.nodes == ("in", "out") and r1.value == 2000.0
    assert c1.value == 2e-6
    assert l1.value == pytest.approx(4e-3 * 1e3)
    assert net.tran is not None and net.tran.tstop == 1e-3
    assert any(".print" in w.message for w in net.warnings)
    assert c1.loc.line == 8  # location of the line that starts the element


def test_param_override_propagates() -> None:
    net = parse_text(NETLIST, overrides={"RR": 1000.0})
    assert net.params["tau"] == pytest.approx(1000.0 * 2e-6)
    with pytest.raises(UsageError, match=r"no \.param nope"):
        parse_text(NETLIST, overrides={"nope": 1.0})


def test_source_waveforms() -> None:
    net = parse_text(
        """t
V1 a 0 PULSE(0 1 1u 2n 3n 4u 10u)
V2 b 0 DC 1 AC 1 0 SIN(0 2 1k 0 0 90)
V3 c 0 PWL(0 0 1m 1 2m 0)
I1 0 d EXP(0 1m 0 1u 5u 2u)
R1 a 0 1
R2 b 0 1
R3 c 0 1
R4 d 0 1
"""
    )
    v1, v2, v3, i1 = net.sources
    assert v1.waveform == Pulse(0, 1, 1e-6, 2e-9, 3e-9, 4e-6, 10e-6)
    assert v2.value == 1.0 and v2.waveform == Sin(0, 2, 1e3, 0, 0, 90)
    assert v3.waveform == Pwl((0, 1e-3, 2e-3), (0, 1, 0))
    assert i1.waveform == Exp(0, 1e-3, 0, 1e-6, 5e-6, 2e-6)
    assert i1.kind is Kind.ISOURCE


def test_waveform_values() -> None:
    pulse = Pulse(0, 1, 1e-6, 1e-6, 1e-6, 2e-6, 10e-6)
    assert list(pulse([0, 1.5e-6, 3e-6, 4.5e-6, 6e-6, 11.5e-6])) == pytest.approx([0, 0.5, 1, 0.5, 0, 0.5])
    assert Pwl((0, 1), (0, 2))([0.25, 5.0]).tolist() == [0.5, 2.0]


def test_shipped_netlists_define_each_parameter_once() -> None:
    for path in sorted(NETLISTS.glob("*.cir")):
        net = parse_file(path)
        assert not [w for w in net.warnings if "defined again" in w.message], path.name


def test_two_pendula_cart_mass_and_bob_mass_are_separate() -> None:
    # The notes' linearisation (seed 003): θ'' = K θ with K = g/M [[(M+m)/l1, m/l1], [m/l2, (M+m)/l2]];
    # the cart adds the zero eigenvalue. With M = 2, m = 1 the two masses must act separately.
    import numpy as np

    from netlistdyn.formulation.compile import compile_netlist

    big_m, m, l1, l2, g = 2.0, 1.0, 1.0, 2.0, 9.81
    k = g / big_m * np.array([[(big_m + m) / l1, m / l1], [m / l2, (big_m + m) / l2]])
    rates = np.sqrt(np.linalg.eigvals(k).astype(complex))
    expected = [*rates, *(-rates), 0.0]
    model = compile_netlist(parse_file(NETLISTS / "two_pendula_cart.cir", {"Mc": big_m, "mb": m}))
    got = np.linalg.eigvals(model.A)
    # 1e-9 relative to the largest rate: a 5-state eigenproblem of O(1) entries.
    for value in expected:
        assert np.min(np.abs(got - value)) <= 1e-9 * float(np.max(np.abs(rates)))


def test_step_param_runs_as_a_sweep(tmp_path) -> None:
    # LTspice's .step (ngspice 39 refuses it): each case is an RC low-pass, eigenvalue -1/(RC).
    from click.testing import CliRunner

    from netlistdyn.cli import main

    path = tmp_path / "step.cir"
    path.write_text("steps\n.param r=1k\nV1 a 0 1\nR1 a b {r}\nC1 b 0 1u\n.step param r list 1k 4k\n")
    net = parse_file(path)
    assert net.step_cases() == [{"r": 1000.0}, {"r": 4000.0}]
    result = CliRunner().invoke(main, ["sweep", str(path), "--format", "json"])
    assert result.exit_code == 0, result.output
    import json

    cases = json.loads(result.stdout)["cases"]
    assert len(cases) == 2
    for case, r in zip(cases, (1e3, 4e3), strict=True):
        assert case["params"]["r"] == r
        ((real, imag),) = case["eigenvalues"]
        assert imag == 0.0
        assert real == pytest.approx(-1 / (r * 1e-6), rel=1e-12)  # closed form of one RC pole


def test_pwl_file_equals_inline_points(tmp_path) -> None:
    # LTspice's PWL file=: two columns, time and value (ngspice 39 has no FILE=).
    (tmp_path / "wave.txt").write_text("0 0\n1u 1\n2u, 0.5\n3u 0\n")
    (tmp_path / "top.cir").write_text("pwl\nV1 a 0 PWL file=wave.txt\nR1 a 0 1\n")
    inline = parse_text("pwl\nV1 a 0 PWL(0 0 1u 1 2u 0.5 3u 0)\nR1 a 0 1\n").element("V1").waveform
    assert parse_file(tmp_path / "top.cir").element("V1").waveform == inline
