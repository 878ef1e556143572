"""One test per SPICE construct: netlistdyn reads the text as ngspice 39 reads it.

Each test parses a netlist with netlistdyn and runs ``ngspice -b`` on the
same text (see :mod:`tests.ngspice_probe`): node voltages of the DC
operating point, or ``.ac`` values, must agree. Where ngspice refuses the
text, netlistdyn must refuse it too. Constructs ngspice 39 does not read
(LTspice's ``Rser=``, ``.step``, one-argument ``.tran``) are compared with
ngspice's reading of the equivalent netlist written out by hand, as stated.
"""

from __future__ import annotations

import numpy as np
import pytest

from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.expressions import evaluate
from netlistdyn.circuit.netlist import Kind
from netlistdyn.frontend.parser import parse_file, parse_text
from tests.ngspice_probe import (
    NgspiceRefused,
    assert_same_op,
    needs_ngspice,
    ngspice_ac,
    ngspice_op,
    ngspice_tran,
    our_ac,
)

pytestmark = needs_ngspice


def same(text: str, **kwargs):
    netlist = parse_text(text)
    assert_same_op(netlist, text, **kwargs)
    return netlist


def both_refuse(text: str, fragment: str) -> None:
    with pytest.raises(NgspiceRefused):
        ngspice_op(text)
    with pytest.raises(NetlistError, match=fragment):
        parse_text(text)


# ---- the silent misreadings of issue #10 ------------------------------------------------


def test_micro_sign_utf8() -> None:
    net = same("micro\nI1 0 a 1\nR1 a 0 10\u00b5\nI2 0 b 1\nR2 b 0 2.2\u00b5Ohm\n")
    assert net.element("R1").value == pytest.approx(1e-5, rel=1e-15)


def test_micro_sign_latin1_file(tmp_path) -> None:
    # An LTspice export: cp1252/Latin-1, µ is the single byte 0xB5.
    text = "latin-1 export\nI1 0 a 1\nR1 a 0 47\u00b5\n"
    path = tmp_path / "ltspice.cir"
    path.write_bytes(text.encode("latin-1"))
    net = parse_file(path)
    assert net.element("R1").value == pytest.approx(47e-6, rel=1e-15)
    assert_same_op(net, text, encoding="latin-1")


def test_greek_mu_is_not_micro_to_ngspice() -> None:
    # ngspice 39 skips U+03BC like a unit letter: 10μ is 10. Same reading, with a warning.
    net = same("greek\nI1 0 a 1\nR1 a 0 10\u03bc\n")
    assert net.element("R1").value == 10.0
    assert any("U+03BC" in w.message for w in net.warnings)


def test_global_node_inside_subcircuit() -> None:
    net = same(
        "global\n.global vdd\nV1 vdd 0 2\nX1 out sub\nRl out 0 1k\n"
        ".subckt sub o\nR1 vdd o 3k\nR2 o 0 1k\n.ends\n"
    )
    assert net.element("X1.R1").nodes == ("vdd", "out")


@pytest.mark.parametrize("value", ["{1000", "'1000", "{1000}}"])
def test_unclosed_brace_or_quote_is_refused(value: str) -> None:
    both_refuse(f"unclosed\nI1 0 a 1\nR1 a 0 {value}\n", "R1")


@pytest.mark.parametrize("line", ["V1 a 0 1 2", "V1 a 0 DC 1 5", "I1 a 0 1 2", "V1 a 0 DC 1 AC 1 2 3"])
def test_extra_source_values_are_refused(line: str) -> None:
    both_refuse(f"extra\n{line}\nR1 a 0 1\n", line.split()[0])


@pytest.mark.parametrize(("line", "volts"), [("V1 a 0 DC 1 DC 5", 5.0), ("V1 a 0 1 DC 5", 1.0)])
def test_repeated_dc_as_ngspice(line: str, volts: float) -> None:
    # Measured: the last DC keyword wins, but a leading value wins over DC keywords.
    net = same(f"dc twice\n{line}\nR1 a 0 1\n")
    assert net.element("V1").value == volts


@pytest.mark.parametrize("separator", ["\f", "\u2028", "\u2029", "\x0b", "\x85"])
def test_only_newlines_end_lines(separator: str) -> None:
    text = f"lines\nI1 0 a 1\nR1 a 0 10\n* comment {separator}R2 a 0 5\nC1 a 0 1u\n"
    net = same(text)
    assert [e.name for e in net.elements] == ["I1", "R1", "C1"]
    assert net.element("C1").loc.line == 5


def test_crlf_and_cr_line_ends() -> None:
    crlf = "crlf\r\nI1 0 a 1\r\nR1 a 0 10\r\n"
    same(crlf)
    # A bare CR ends a line (old Mac files). ngspice 39 reads such a file as one title
    # line; we read its lines (issue #10 asks for it), which is more, not a different meaning.
    net = parse_text("cr\rI1 0 a 1\rR1 a 0 10\r")
    assert [e.name for e in net.elements] == ["I1", "R1"]


# ---- parameters and expressions ----------------------------------------------------------


def test_param_redefinition_last_wins_everywhere() -> None:
    # ngspice sorts .param by dependency: b={a} sees the *last* a, and M/m are one name.
    net = same("redefinition\n.param M=2 m=0.3\n.param a=1 b={a} a=2\nV1 x 0 {b}\nI1 0 y 1\nR1 y 0 {M}\n")
    assert net.params["b"] == 2.0 and net.params["m"] == 0.3
    assert sum("defined again" in w.message for w in net.warnings) == 2


EXPRESSIONS = [
    "-2**2",
    "2**-1",
    "(-8)**(1/3)",
    "2^3^2",
    "(-2)**3",
    "2+-3**2",
    "2*-3**2",
    "-3**2*2",
    "3 - -2**2",
    "2**-2**2",
    "2/-2**2",
    "+-2**2",
    "1?2:3?4:5",
    "0?2:0?4:5",
    "1+1?7:8",
    "7%3",
    "-5%3",
    "5%-3",
    "int(-2.7)",
    "nint(-2.5)",
    "nint(3.5)",
    "pow(-2,3)",
    "pwr(-8,1/3)",
    "min(3,4,5)",
    "max(1,2)*-1",
    "1&&0",
    "0||2",
    "!0",
    "2>=2",
    "1.5e3k",
    "1meg*2",
    "1mil",  # 1m: ngspice 39 has no "mil" inside expressions (a value field's 1mil is 25.4u)
    "sgn(-3)",
    "atan(1)",
    "asinh(1)",
    "log10(100)",
    "ln(2)",
    "ternary_fcn(1,2,3)",
    "floor(1.7)+ceil(1.2)",
]


def test_expressions_as_ngspice() -> None:
    lines = [f"V{k} n{k} 0 {{{expr}}}\nR{k} n{k} 0 1" for k, expr in enumerate(EXPRESSIONS)]
    theirs = ngspice_op("expressions\n" + "\n".join(lines) + "\n")
    for k, expr in enumerate(EXPRESSIONS):
        # 1e-12: ngspice prints 15 significant digits.
        assert evaluate(expr, {}) == pytest.approx(theirs[f"n{k}"], rel=1e-12, abs=1e-300), expr


@pytest.mark.parametrize("expr", ["sqrt(-4)", "1/0", "0**-1", "pow(-8,1/3)", "1e400", "4k7"])
def test_bad_expressions_refused_as_ngspice(expr: str) -> None:
    both_refuse(f"bad\nV1 a 0 {{{expr}}}\nR1 a 0 1\n", "V1")


def test_log_with_two_arguments_refused() -> None:
    # ngspice 39 silently evaluates log(2,10) as ln(10); we refuse rather than guess.
    assert ngspice_op("log\nV1 a 0 {log(2,10)}\nR1 a 0 1\n")["a"] == pytest.approx(
        2.302585092994046, rel=1e-12
    )
    with pytest.raises(NetlistError, match="log takes 1"):
        parse_text("log\nV1 a 0 {log(2,10)}\nR1 a 0 1\n")


@pytest.mark.parametrize(("token", "value"), [("4k7", 4000.0), ("1u5", 1e-6), ("2R2", 2.0), ("4meg7", 4e6)])
def test_rkm_notation_read_as_ngspice(token: str, value: float) -> None:
    net = same(f"rkm\nI1 0 a 1\nR1 a 0 {token}\n")
    assert net.element("R1").value == value
    assert any("RKM" in w.message for w in net.warnings)


def test_bare_parameter_name_as_value() -> None:
    net = same("bare\n.param rval=2.2k\nI1 0 a 1m\nR1 a 0 rval\n")
    assert net.element("R1").value == 2200.0


def test_func() -> None:
    same(".func\n.func par(a,b) = {a*b/(a+b)}\nI1 0 a 1m\nR1 a 0 {par(1k, 3k)}\n")


def test_if_elseif_else() -> None:
    for x, expected in ((1, 1.0), (2, 2.0), (3, 3.0)):
        text = (
            f".if\n.param x={x}\nI1 0 a 1\n.if (x == 1)\nR1 a 0 1\n.elseif (x == 2)\nR1 a 0 2\n"
            ".else\nR1 a 0 3\n.endif\n"
        )
        net = same(text)
        assert net.element("R1").value == expected


# ---- subcircuits ------------------------------------------------------------------------


def test_subcircuit_params_and_overrides() -> None:
    text = (
        "params\n.param g=3\n.subckt div in out params: ra=1k rb={2*ra}\n"
        "R1 in out {ra}\nR2 out 0 {rb*g/3}\n.ends\n"
        "V1 in 0 1\nX1 in o1 div\nX2 in o2 div ra=2k\nX3 in o3 div params: rb=500\n"
    )
    net = same(text)
    assert net.element("X2.R2").value == 4000.0


def test_subcircuit_hspice_params_nested_scopes() -> None:
    text = (
        "nested\n.subckt inner a b r=1\nR1 a b {r}\n.ends\n"
        ".subckt outer a b r=10\n.param twice={2*r}\nX1 a m inner r={twice}\nX2 m b inner\n.ends\n"
        "V1 in 0 1\nXA in o outer r=100\nRL o 0 1k\nXB in p outer\nRM p 0 1k\n"
    )
    net = same(text)
    assert net.element("XA.X1.R1").value == 200.0
    assert net.element("XA.X2.R1").value == 1.0


# ---- element keyword forms ----------------------------------------------------------------


def test_keyword_forms_on_passives_and_sources() -> None:
    text = (
        "keywords\nV1 a 0 dc=2 ac=1\nR1 a b r=1k noisy=0\nR2 b 0 resistance=3k m=2\n"
        "I1 0 c dc 1m\nR3 c 0 1k tc1=0.1 dtemp=1\nR4 c 0 2k tc1=0.01 tc2=0.001 temp=37\n"
        "C1 b 0 c=1u m=3 ic=0.5\nL1 c 0 l=1m m=2 ic=1m\n"
    )
    net = same(text)
    assert net.element("C1").value == pytest.approx(3e-6) and net.element("C1").ic == 0.5
    assert net.element("L1").value == pytest.approx(0.5e-3) and net.element("L1").ic == 1e-3
    # .ac through R1, R2 (m=2), C1 (m=3): reads the same magnitudes
    for f in (10.0, 1e3):
        assert our_ac(net, "b", f, "V1") == pytest.approx(ngspice_ac(text, "b", f), rel=1e-9)


def test_resistor_ac_value_warned() -> None:
    # ngspice uses ac= only in .ac analysis; the model (one for all analyses) uses r.
    text = "acres\nV1 a 0 dc 1 ac 1\nR1 a b 1k ac=2k\nR2 b 0 1k\n"
    net = same(text)
    assert any("ac=2000" in w.message for w in net.warnings)
    assert ngspice_ac(text, "b", 1e3) == pytest.approx(1 / 3, rel=1e-9)


def test_resistor_models() -> None:
    text = (
        "models\nI1 0 a 1m\nR1 a 0 rmod\n.model rmod R(r=5k)\n"
        "I2 0 b 1m\nR2 b 0 7k rtc\n.model rtc R(tc1=0.01)\n"
        "I3 0 c 1m\nR3 c 0 rsh l=10u w=1u\n.model rsh R(rsh=3)\n"
    )
    net = same(text)
    assert net.element("R3").value == pytest.approx(30.0)


def test_value_and_ic_directives_stored() -> None:
    net = parse_text("ic\nV1 a 0 1\nR1 a b 1k\nC1 b 0 1u\n.ic v(b)=0.25\n.tran 1u 1m uic\n")
    assert [(ic.node, ic.value) for ic in net.initial_conditions] == [("b", 0.25)]


def test_port_source_with_z0() -> None:
    text = "port\nV1 a 0 dc 1 ac 1 portnum 1 z0 25\nR1 a 0 50\n"
    net = same(text)
    assert net.sources[0].name == "V1"
    assert our_ac(net, "a", 1e3, "V1") == pytest.approx(ngspice_ac(text, "a", 1e3), rel=1e-9)


def test_distof_has_no_effect() -> None:
    same("distof\nV1 a 0 1 distof1 1 0 distof2 0.5\nR1 a 0 50\n")


# ---- behavioural sources ---------------------------------------------------------------


def test_linear_b_e_g_sources() -> None:
    text = (
        "behavioural\nV1 a 0 2\nR1 a 0 1k\nI1 0 c 1m\nR5 c 0 3k\n"
        "B1 b 0 V={2*v(a)-v(a,c)/4+3*i(V1)+0.5}\nR2 b 0 1k\n"
        "B2 0 d I={v(b)*1m - 2*i(V1)}\nR3 d 0 1k\n"
        "E1 e 0 value={2*v(d)+v(c)}\nR4 e 0 1k\nG1 0 f cur={v(e)/1k}\nR6 f 0 500\n"
        "E2 g 0 vol='v(f)*0.5'\nR7 g 0 1k\n"
    )
    net = same(text)
    assert any(e.kind is Kind.CCVS for e in net.elements)


@pytest.mark.parametrize(
    ("line", "fragment"),
    [
        ("B1 b 0 V={v(a)*v(a)}", "product"),
        ("B1 b 0 V={sin(v(a))}", "sin"),
        ("B1 b 0 V={v(a)**2}", r"\*\*"),
        ("B1 b 0 I={time*1m}", "time"),
        ("E1 b 0 value={v(a) > 1 ? 1 : 0}", "nonlinear"),
    ],
)
def test_nonlinear_behavioural_read_as_nonlinear(line: str, fragment: str) -> None:
    text = f"nonlinear\nV1 a 0 1\nR1 a 0 1\n{line}\nR2 b 0 1\n"
    ngspice_op(text)  # ngspice reads them (nonlinear): one nonlinear element (issue #14), not linear terms
    (source,) = [e for e in parse_text(text).elements if e.name[0] in "BE"]
    assert source.kind in (Kind.BVOLTAGE, Kind.BCURRENT), fragment


def test_poly_sources_as_ngspice() -> None:
    """SPICE2 POLY on E, F, G and H: first-order terms compile, the constant p0 is a model input;
    one coefficient is p0 for ngspice 39 (``E1 b 0 POLY(1) a 0 2`` is 2 V, not 2·v(a)). Higher
    terms make a nonlinear expression, handled as the B source it equals."""
    text = (
        "poly\nV1 in 0 3\nR1 in a 1k\nR0 a 0 2k\nVs x 0 0\nR3 in x 2k\n"
        "E1 b 0 POLY(1) a 0 2\nR2 b 0 1k\nE2 c 0 POLY(2) a 0 in 0 0.5 2 -0.25\nR4 c 0 1k\n"
        "G1 0 d POLY(1) a 0 0 1m\nR5 d 0 1k\nF1 0 e POLY(2) V1 Vs 1m 0.5 0.25\nR6 e 0 1k\n"
        "H1 f 0 POLY(1) Vs 0 100 0\nR7 f 0 1k\n"
    )
    net = same(text)
    assert any(w.message.startswith("E1: the constant term 2") for w in net.warnings)


def test_random_sources_use_their_dc_value() -> None:
    """TRNOISE and TRRANDOM: the DC value in op (and in the model's inputs); no transient."""
    same("noise\nV1 a 0 DC 2 TRNOISE(1n 1n 0 0)\nR1 a b 1k\nR2 b 0 1k\nI1 0 b DC 1m trrandom(2 10m 0 1)\n")


def test_dc_keyword_without_value_is_zero() -> None:
    net = same("dc\nV1 a 0 DC sin(0.5 1 1k)\nR1 a b 1k\nR2 b 0 1k\nI1 0 b 1m\n")
    assert any("DC without a value" in w.message for w in net.warnings)


def test_unbraced_expression_after_keyword() -> None:
    """ngspice's numparam: ``R=va+vb`` is an expression; a positional or blank-separated one is not."""
    net = same("kw\n.param va=400 vb=600\nV1 a 0 1\nR1 a b R=va+vb\nR2 b 0 r=va*2\n")
    assert net.element("R1").value == pytest.approx(1000.0, rel=1e-15)
    both_refuse("kw\n.param va=400 vb=600\nV1 a 0 1\nR1 a 0 va+vb\n", "va\\+vb")
    both_refuse("kw\n.param va=400 vb=600\nV1 a 0 1\nR1 a 0 R = va + vb\n", "'\\+'")


def test_global_param_is_ignored_as_ngspice() -> None:
    net = same("gp\n.global_param rr=2k\nV1 a 0 1\nR1 a b 1k\nR2 b 0 1k\n")
    assert any(".global_param" in w.message for w in net.warnings)
    both_refuse("gp\n.global_param rr=2k\nV1 a 0 1\nR1 a 0 {rr}\n", "rr")


@pytest.mark.parametrize(("line", "what"), [("Q1 a b 0 qmod", "bipolar"), ("M1 a b 0 0 mmod", "MOSFET")])
def test_nonlinear_devices_refused_in_one_line(line: str, what: str) -> None:
    with pytest.raises(NetlistError, match=what) as info:
        parse_text(f"device\nV1 a 0 1\nR1 a 0 1\n{line}\n")
    assert "\n" not in str(info.value)


# ---- LTspice constructs (ngspice 39 refuses them: compared with the equivalent netlist) ----


def test_ltspice_parasitics_equal_explicit_elements() -> None:
    ltspice = "lt\nV1 in 0 dc 0 ac 1\nL1 in a 10u Rser=0.5 Cpar=10p\nC1 a 0 1u Rser=0.1 Lser=1n Rpar=1meg\n"
    explicit = (
        "explicit\nV1 in 0 dc 0 ac 1\nL1 in l1.rser 10u\nR1 l1.rser a 0.5\nC2 in a 10p\n"
        "C1 a c1.rser 1u\nR2 c1.rser c1.lser 0.1\nL2 c1.lser 0 1n\nR3 a 0 1meg\n"
    )
    with pytest.raises(NgspiceRefused):
        ngspice_op(ltspice)  # ngspice 39: "unknown parameter (rser)"
    net = parse_text(ltspice)
    for f in (1e3, 5e4, 1e6):
        assert our_ac(net, "a", f, "V1") == pytest.approx(ngspice_ac(explicit, "a", f), rel=1e-9)


def test_ltspice_tran_and_backanno_and_step() -> None:
    net = parse_text("lt\nV1 a 0 1\nR1 a 0 1\n.tran 2u\n.backanno\n.step param R 1 3 1\n")
    assert net.tran is not None and net.tran.tstop == 2e-6
    assert net.steps[0].values == (1.0, 2.0, 3.0)
    net = parse_text("lt\nV1 a 0 1\nR1 a 0 1\n.tran 0 5m 0 1u\n")
    assert net.tran is not None and net.tran.tstop == 5e-3 and net.tran.tmax == 1e-6


# ---- .lib sections and includes -------------------------------------------------------------


def test_lib_section(tmp_path) -> None:
    (tmp_path / "parts.lib").write_text(
        "* library\n.lib fast\nR1 a 0 1k\n.endl\n.lib slow\nR1 a 0 10k\n.endl\n"
    )
    text = "lib\nI1 0 a 1m\n.lib 'parts.lib' slow\n"
    (tmp_path / "top.cir").write_text(text)
    net = parse_file(tmp_path / "top.cir")
    assert net.element("R1").value == 10e3
    assert_same_op(net, text.replace("'parts.lib'", str(tmp_path / "parts.lib")))


# ---- source waveforms ------------------------------------------------------------------------


def test_pulse_defaults_and_period_wrapping() -> None:
    # TR+PW+TF > PER (each period is cut at PER: a jump back to V1 there), PW = 0 (means TSTOP),
    # and all defaults (PER = TSTOP: the value at TSTOP is the pulse's, not V1).
    text = (
        "pulse\nV1 a 0 PULSE(0 1 0 3u 3u 5u 10u)\nR1 a 0 1\nV2 b 0 PULSE(0 1 1u 1u 1u 0 4u)\nR2 b 0 1\n"
        "V3 c 0 PULSE(0 2)\nR3 c 0 1\n.tran 1u 20u\n"
    )
    net = parse_text(text)
    table = ngspice_tran(text, ["v(a)", "v(b)", "v(c)"])
    time = table[:, 0]
    for column, name in enumerate(("V1", "V2", "V3"), start=1):
        wave = net.element(name).waveform.resolved(net.tran.tstep, net.tran.tstop)
        per = wave.per
        # ngspice's own time points carry rounding (its last point is 1.99999999999999847e-05,
        # not 2e-05); at an exact multiple k·PER (k ≥ 1), where a cut period jumps back to V1,
        # ngspice's point is the value before the jump (k = 1) or after it (k ≥ 2, an accident of
        # rounding): there it must be one of the two limits.
        cycles = (time - wave.td) / per
        exact = (np.abs(cycles - np.round(cycles)) < 1e-9) & (np.round(cycles) >= 1)
        # 1e-9 of the 1-2 V swing: ngspice computes the same linear ramps in double precision.
        assert np.max(np.abs(wave(time[~exact]) - table[~exact, column])) < 1e-9, name
        either = np.minimum(
            np.abs(wave(time[exact]) - table[exact, column]),
            np.abs(wave.left(time[exact]) - table[exact, column]),
        )
        assert np.all(either < 1e-9), name


def test_pwl_td_and_repeat() -> None:
    text = (
        "pwl\nV1 a 0 PWL(0 0 1u 1 2u 0.5 3u 0) r=1u td=0.5u\nR1 a 0 1\n"
        "V2 b 0 PWL(0 0 1u 1 2u 0) td=2u\nR2 b 0 1\n.tran 0.1u 10u\n"
    )
    net = parse_text(text)
    table = ngspice_tran(text, ["v(a)", "v(b)"])
    for column, name in enumerate(("V1", "V2"), start=1):
        wave = net.element(name).waveform
        # 1e-9 of the 1 V swing: the same linear interpolation in double precision.
        assert np.max(np.abs(wave(table[:, 0]) - table[:, column])) < 1e-9, name


def test_ltspice_coupling_of_three_inductors() -> None:
    # LTspice couples every pair; ngspice 39 refuses three names, so compare with the three Ks.
    head = "k3\nV1 a 0 dc 0 ac 1\nR1 a b 1\nL1 b 0 1m\nL2 c 0 2m\nR2 c 0 1\nL3 d 0 3m\nR3 d 0 1\n"
    ltspice = head + "K1 L1 L2 L3 0.5\n"
    explicit = head + "K1 L1 L2 0.5\nK2 L1 L3 0.5\nK3 L2 L3 0.5\n"
    with pytest.raises(NgspiceRefused):
        ngspice_op(ltspice)
    net = parse_text(ltspice)
    assert sum(e.kind is Kind.COUPLING for e in net.elements) == 3
    for f in (10.0, 1e3, 1e5):
        assert our_ac(net, "d", f, "V1") == pytest.approx(ngspice_ac(explicit, "d", f), rel=1e-9)


def test_linear_behavioural_sources_compile() -> None:
    # The compiled state-space model of a circuit with B sources has the natural frequencies of
    # the independent MNA pencil of the same reading (whose DC solution matches ngspice above).
    from netlistdyn.formulation.compile import compile_netlist
    from tests.mna import build_mna

    text = (
        "b dynamics\nV1 a 0 2\nR1 a x 1k\nC1 x 0 1u\nB1 b 0 V={2*v(x)-v(x,c)/4+3*i(V1)+0.5}\n"
        "R2 b c 1k\nC2 c 0 2u\nB2 0 d I={v(b)*1m - 2*i(V1)}\nR3 d 0 1k\nC3 d 0 3u\n"
    )
    net = same(text)
    got = np.sort_complex(np.linalg.eigvals(compile_netlist(net).A))
    expected = np.sort_complex(build_mna(net).finite_eigenvalues())
    # 1e-9 relative: eigenvalues of a 3-state model with kΩ·µF time constants.
    assert np.allclose(got, expected, rtol=1e-9, atol=0)


def test_instance_parameters_replace_body_params_and_see_each_other() -> None:
    # Measured on ngspice 39 (Xyce's ISSUE_405 test): par3='par1+par2' uses the instance's own
    # par1, par2 and overrides the body's ".param par3=..." at every level.
    text = (
        "instance params\n.subckt simple in out params: par1=2 par2=2 par3='par1*par2*2'\n.param par3=3000\n"
        "Xtest2 in out simple2 par3='par3'\n.ends\n"
        ".subckt simple2 in out params: par1=2 par2=80 par3='par1*par2/4'\n.param par3=500\n"
        "Rinside in out 'par3'\n.ends\n"
        ".param r=7\n.subckt one a b r=1\nR1 a b {r}\n.ends\n"
        "V1 1 0 1\nR1 1 2 1\nXtest 2 0 simple par1=2 par2=3 par3='par1+par2'\n"
        "I1 0 3 1\nX3 3 0 one r={r*2}\n"
    )
    net = same(text)
    assert net.element("Xtest.Xtest2.Rinside").value == 5.0
    assert net.element("X3.R1").value == 14.0


def test_temperature_coefficients_with_options_tnom_and_temp() -> None:
    net = same(
        ".options\nI1 0 a 1\nR1 a 0 10 tc1=0.1\nI2 0 b 1\nR2 b 0 10 tc1=0.01 tc2=0.001\n"
        ".options tnom=20 temp=40\n"
    )
    assert net.element("R1").value == pytest.approx(10 * (1 + 0.1 * 20), rel=1e-12)
