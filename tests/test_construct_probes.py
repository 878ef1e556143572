"""One small netlist per construct of issue #10, judged against ngspice's own reading.

Each probe is a netlist using one construct. ``tests/ngspice_reading.classify``
builds the reference from ngspice's expanded listing (checked against
ngspice's op/ac) and compares netlistdyn's eigenvalues and transfer values with
it. The expected outcome is today's, recorded so that every change shows:

* ``agree`` — read as ngspice reads it;
* ``refused`` — refused with a one-line ``file:line: message`` (fails, saying
  "move it to agree", once the construct is read and agrees);
* ``wrong`` — a silent misreading (strict xfail: once fixed it fails until
  moved to ``agree``);
* ``ngspice-refuses`` — ngspice 39 itself refuses the file, so netlistdyn must
  refuse it too; ``accepts-invalid`` marks one it still accepts (strict xfail);
* ``behavioural`` — a linear B source or E/G ``value=``: ngspice reads it, and the
  model must agree with ngspice's reading of ``EQUIVALENT`` (the same circuit in
  controlled sources), or be refused in one line;
* ``other-simulator`` — ngspice 39 refuses a construct of LTspice, HSPICE or
  Xyce that issue #10 asks netlistdyn to read: refused with one line, or, once
  accepted, the model must agree with ngspice's reading of ``EQUIVALENT``.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import netlistdyn
from netlistdyn.base.errors import NetlistError

from .ngspice_reading import (
    ReferenceUnavailable,
    build_reference,
    classify_text,
    compare_model,
    ngspice_available,
)

pytestmark = pytest.mark.skipif(not ngspice_available(), reason="ngspice is not installed")

RC = "V1 in 0 1\nR1 in a 1k\nC1 a 0 1u\n"
# What a construct of another simulator (LTspice, HSPICE, Xyce) means, written so
# that ngspice reads it; internal nodes carry a dot so that they are not compared.
EQUIVALENT: dict[str, bytes] = {
    "ltspice_rser": b"r\nV1 in 0 1\nR1 in a 10\nL1 a l1.ser 1m\nRL1ser l1.ser b 0.5\nC1 b 0 1u\n",
    "ltspice_source_rser_cpar": (
        b"r\nV1 v1.rser 0 1\nRV1ser in v1.rser 0.5\nCV1par in 0 1n\nR1 in a 1k\nC1 a 0 1u\n"
    ),
    "value_keyword": b"k\nV1 in 0 1\nR1 in a {2*500}\nC1 a 0 1u\n",
    "tran_one_argument": b"t\n" + RC.encode(),
    "step_param": b"s\n.param rr=1k\nV1 in 0 1\nR1 in a {rr}\nC1 a 0 1u\n",
    "backanno": b"b\n" + RC.encode(),
    # Linear behavioural sources: ngspice reads them, but the reference builder stamps only
    # linear element kinds, so they are compared with the same circuit in controlled sources.
    "b_source_linear": b"b\n" + RC.encode() + b"E1 b b1.n1 a 0 2\nE2 b1.n1 0 in 0 -0.5\nR2 b 0 1k\n",
    "e_value_linear": b"e\n" + RC.encode() + b"E1 b 0 a 0 2\nR2 b 0 1k\n",
}
ONE_LINE = re.compile(r"^\S.*:\d+: \S.*$")

# name: (netlist bytes, expected outcome today)
PROBES: dict[str, tuple[bytes, str]] = {
    "mu_utf8_b5": ("mu\nV1 in 0 dc 1\nR1 in out 1k\nC1 out 0 10\u00b5\n".encode(), "agree"),
    "mu_utf8_3bc": ("mu\nV1 in 0 dc 1\nR1 in out 1k\nC1 out 0 10\u03bc\n".encode(), "agree"),
    "mu_latin1": (b"mu\nV1 in 0 dc 1\nR1 in out 1k\nC1 out 0 10\xb5\n", "agree"),
    "global": (
        b"g\n.global vcc\nVs vcc 0 2\n.subckt st in out\nR1 vcc out 1k\nC1 out 0 1u\nR2 in out 2k\n.ends\n"
        b"V1 a 0 1\nX1 a b st\nR3 b 0 4.7k\n",
        "agree",
    ),
    "unclosed_brace": (b"u\nV1 in 0 1\nR1 in a {1000\nC1 a 0 1u\n", "ngspice-refuses"),
    "extra_value": (b"x\nV1 in 0 1 2\nR1 in a 1k\nC1 a 0 1u\n", "ngspice-refuses"),
    "extra_dc_value": (b"x\nV1 in 0 DC 1 5\nR1 in a 1k\nC1 a 0 1u\n", "ngspice-refuses"),
    "formfeed_in_comment": (b"f\n* note \x0c R9 in 0 1\n" + RC.encode(), "agree"),
    "u2028_in_comment": ("f\n* note \u2028R9 in 0 1\n".encode() + RC.encode(), "agree"),
    "ltspice_rser": (b"r\nV1 in 0 1\nR1 in a 10\nL1 a b 1m Rser=0.5\nC1 b 0 1u\n", "other-simulator"),
    "ltspice_source_rser_cpar": (
        b"r\nV1 in 0 1 Rser=0.5 Cpar=1n\nR1 in a 1k\nC1 a 0 1u\n",
        "other-simulator",
    ),
    # issue #27: source forms (their transients and operating points: tests/test_ngspice_sources.py)
    "sin_seven_values": (b"s\nV1 in 0 SIN( 0 1 200 0 0 0 0 )\nR1 in a 1k\nC1 a 0 1u\n", "agree"),
    "am_source": (b"a\nV1 in 0 AM(1 0.5 100 1k 1m 30 60)\nR1 in a 1k\nC1 a 0 1u\n", "agree"),
    "sffm_source": (b"f\nV1 in 0 SFFM(0.1 1 1k 2 100)\nR1 in a 1k\nC1 a 0 1u\n", "agree"),
    "pulse_ncycles": (b"p\nV1 in 0 PULSE(0 1 0 1m 1m 1m 4m 2)\nR1 in a 1k\nC1 a 0 1u\n", "agree"),
    "subckt_instance_m": (
        b"m\n.subckt rc a b\nR1 a b 1k\nC1 b 0 1u\nL1 b 0 1m\n.ends\nV1 in 0 1\nX1 in out rc M = 10\n"
        b"R2 out 0 1k\n",
        "agree",
    ),
    "subckt_params": (
        b"p\n.subckt rc a b params: r=1k c=1n\nR1 a b {r}\nC1 b 0 {c}\n.ends\n"
        b"V1 in 0 1\nX1 in m rc r=2k\nX2 m out rc c={2n}\n",
        "agree",
    ),
    "subckt_hspice_params": (
        b"p\n.subckt rc a b r=1k c=1n\nR1 a b {r}\nC1 b 0 {c}\n.ends\n"
        b"V1 in 0 1\nX1 in m rc r=2k\nX2 m out rc\n",
        "agree",
    ),
    "subckt_nested_params": (
        b"p\n.subckt inner a b params: r=1k\nR1 a b {r}\n.ends\n.subckt outer a b params: k=2\n"
        b"X1 a m inner r={k*1k}\nC1 m b 1u\n.ends\nV1 in 0 1\nX1 in 0 outer k=3\n",
        "agree",
    ),
    "source_keywords": (b"k\nV1 in 0 dc=0 ac=1\nR1 in a 1k\nC1 a 0 1u\n", "agree"),
    "passive_keywords": (b"k\nV1 in 0 1\nR1 in a R=1k\nC1 a 0 C=1u\nL1 a 0 L=1m\n", "agree"),
    "value_keyword": (b"k\nV1 in 0 1\nR1 in a value={2*500}\nC1 a 0 1u\n", "other-simulator"),
    "multiplier": (b"m\nV1 in 0 1\nR1 in a 1k m=2\nC1 a 0 1u m=3\nL1 a 0 1m m=2\n", "agree"),
    "r_noisy": (b"n\nV1 in 0 1\nR1 in a 1k noisy=0\nC1 a 0 1u\n", "agree"),
    "element_ic": (b"i\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u IC=1\nL1 a 0 1m IC=1m\n", "agree"),
    "dot_ic": (b"i\n" + RC.encode() + b".ic v(a)=1\n", "agree"),
    "dot_func": (b"f\n.func half(x) {x/2}\nV1 in 0 1\nR1 in a {half(2k)}\nC1 a 0 1u\n", "agree"),
    "dot_if": (
        b"i\n.param sel=1\n.if (sel == 1)\nR1 in a 1k\n.else\nR1 in a 2k\n.endif\nV1 in 0 1\nC1 a 0 1u\n",
        "agree",
    ),
    "rkm_4k7": (b"r\nV1 in 0 1\nR1 in a 4k7\nC1 a 0 1u\n", "agree"),
    "bare_parameter": (b"b\n.param rr=2k\nV1 in 0 1\nR1 in a rr\nC1 a 0 1u\n", "agree"),
    "atto_is_not_a_suffix": (b"a\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1a\nR2 a 0 1a\n", "agree"),
    "case_insensitive_param": (b"c\n.param M=2 m=3\nV1 in 0 1\nR1 in a {M*1k}\nC1 a 0 1u\n", "agree"),
    "port_source": (b"p\nV1 in 0 dc 0 ac 1 portnum 1 z0 50\nR1 in a 1k\nC1 a 0 1u\n", "agree"),
    "distof": (b"d\nV1 in 0 dc 0 ac 1 distof1 0.1\nR1 in a 1k\nC1 a 0 1u\n", "agree"),
    "r_model_card": (b"m\n.model rmod r\nV1 in 0 1\nR1 in a rmod 1k\nC1 a 0 1u\n", "agree"),
    "c_model_card": (b"m\n.model cmod c\nV1 in 0 1\nR1 in a 1k\nC1 a 0 cmod 1u\n", "agree"),
    "title_directive": (b"t\n.title my circuit\n" + RC.encode(), "agree"),
    "gnd_alias": (b"g\nV1 in GND 1\nR1 in a 1k\nC1 a gnd 1u\n", "agree"),
    "tran_one_argument": (b"t\n" + RC.encode() + b".tran 2u\n", "other-simulator"),
    "step_param": (
        b"s\n.param rr=1k\nV1 in 0 1\nR1 in a {rr}\nC1 a 0 1u\n.step param rr list 1k 2k\n",
        "other-simulator",
    ),
    "backanno": (b"b\n" + RC.encode() + b".backanno\n", "other-simulator"),
    "pwl_td": (b"p\nV1 in 0 pwl(0 0 1m 1) td=1m r=0\nR1 in a 1k\nC1 a 0 1u\n", "refused"),
    "ternary": (b"t\n.param a=1\nV1 in 0 1\nR1 in a {a>0 ? 1k : 2k}\nC1 a 0 1u\n", "agree"),
    "b_source_linear": (
        b"b\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u\nB1 b 0 V=2*V(a)-V(in)/2\nR2 b 0 1k\n",
        "behavioural",
    ),
    "e_value_linear": (
        b"e\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u\nE1 b 0 value={2*V(a)}\nR2 b 0 1k\n",
        "behavioural",
    ),
    "kicad_export_names": (
        b".title KiCad schematic\nR1 Net-_C1-Pad2_ Net-_R1-Pad2_ 1k\nV1 Net-_R1-Pad2_ GND DC 0 AC 1\n"
        b"C1 /lowpass Net-_C1-Pad2_ 100n\nR2 /lowpass GND 10k\nC2 Net-_C1-Pad2_ GND 47n\n.ac dec 10 1 1Meg\n",
        "agree",
    ),
    "kicad_dc_parenthesised": (b"k\nV1 /vdd GND dc(5)\nR1 /vdd /a 1k\nC1 /a GND 1u\n", "agree"),
    "kicad_probe_alli": (
        b"k\n.save all\n.probe alli\nV1 in GND DC 0 AC 1\nR1 in a 1k\nC1 a GND 1u\n",
        "agree",
    ),
    "bjt": (b"q\nV1 in 0 1\nR1 in a 1k\nQ1 a a 0 qmod\n.model qmod npn\n", "refused"),
    # ngspice's numparam reads an unbraced expression after key= (no blanks), nowhere else.
    "keyword_unbraced_expression": (
        b"k\n.param va=400 vb=600\nV1 in 0 1\nR1 in a R=va+vb\nC1 a 0 C=va*vb*1n\n",
        "agree",
    ),
    "positional_unbraced_expression": (
        b"k\n.param va=400 vb=600\nV1 in 0 1\nR1 in a va+vb\nC1 a 0 1u\n",
        "ngspice-refuses",
    ),
    "keyword_spaced_expression": (
        b"k\n.param va=400 vb=600\nV1 in 0 1\nR1 in a R = va + vb\nC1 a 0 1u\n",
        "ngspice-refuses",
    ),
    # Xyce's .global_param: ngspice 39 skips the line (its names stay undefined).
    "global_param_unused": (b"g\n.global_param rr=2k\n" + RC.encode(), "agree"),
    "global_param_used": (b"g\n.global_param rr=2k\nV1 in 0 1\nR1 in a {rr}\nC1 a 0 1u\n", "ngspice-refuses"),
    "dc_keyword_without_value": (
        b"d\nV1 in 0 DC sin(0.5 1 1k)\nR1 in a 1k\nC1 a 0 1u\nI1 0 a DC pulse(1m 2m 0 1u 1u 1m 2m)\n",
        "agree",
    ),
    # SPICE2 POLY: ngspice makes it an XSPICE spice2poly model, read back by the reference.
    "poly_e_g_first_order": (
        b"p\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u\nE1 b 0 POLY(2) a 0 in 0 0 1 -0.5\nR2 b 0 1k\nC2 b 0 1n\n"
        b"G1 a 0 POLY(1) b 0 0 0.1m\n",
        "agree",
    ),
    "poly_f_h_in_subckt": (
        b"p\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u\n.subckt amp i o\nVs i m 0\nRm m 0 1k\n"
        b"H1 o 0 POLY(1) Vs 0 3\nF1 0 o POLY(1) Vs 0 0.5 0\n.ends\nX1 a b amp\nR2 b 0 1k\n",
        "agree",
    ),
    "trnoise_source": (
        b"n\nV1 in 0 DC 0.5 trnoise(1n 1n 0 0)\nR1 in a 1k\nC1 a 0 1u\nI1 0 a DC 1m trrandom(2 10m 0 1)\n",
        "agree",
    ),
}


@pytest.mark.parametrize("name", sorted(PROBES))
def test_construct_probe(name: str, tmp_path: Path) -> None:
    text, expect = PROBES[name]
    text += b".end\n"
    if expect in ("ngspice-refuses", "accepts-invalid"):
        path = tmp_path / "probe.cir"
        path.write_bytes(text)
        with pytest.raises(ReferenceUnavailable):
            build_reference(path)
        try:
            netlistdyn.compile(path)
        except NetlistError as exc:
            assert ONE_LINE.match(str(exc).strip()), str(exc)
            if expect == "accepts-invalid":
                pytest.fail("now refused as ngspice refuses it: mark it 'ngspice-refuses'")
            return
        if expect == "accepts-invalid":
            pytest.xfail("netlistdyn accepts a file ngspice 39 refuses")
        pytest.fail("netlistdyn accepts a file ngspice 39 refuses")
    if expect in ("other-simulator", "behavioural"):
        path = tmp_path / "probe.cir"
        path.write_bytes(text)
        if expect == "other-simulator":
            with pytest.raises(ReferenceUnavailable):
                build_reference(path)
        try:
            netlistdyn.compile(path)
        except NetlistError as exc:
            assert ONE_LINE.match(str(exc).strip()), str(exc)
            return
        same = tmp_path / "equivalent.cir"
        same.write_bytes(EQUIVALENT[name] + b".end\n")
        _, ref = build_reference(same)
        outcome = compare_model(path, ref)
        assert outcome.status == "agree", (
            f"accepted, but not as ngspice reads the equivalent: {outcome.detail}"
        )
        return
    outcome = classify_text(text, tmp_path)
    assert outcome.status != "no-reference", outcome.detail
    if expect == "wrong":
        if outcome.status == "wrong":
            pytest.xfail(f"known misreading: {outcome.detail}")
        pytest.fail(f"no longer misread ({outcome.status}: {outcome.detail}): update the expectation")
    assert outcome.status != "wrong", outcome.detail
    if expect == "agree":
        assert outcome.status == "agree", outcome.detail
    else:
        assert outcome.status == "refused", f"now agrees with ngspice ({outcome.detail}): move it to 'agree'"
        assert ONE_LINE.match(outcome.detail), outcome.detail
