"""Nonlinear netlists (issue #14): parsing, operating point and linearisation.

References are independent of netlistdyn: ngspice 39's own ``.op`` and its
``.ac`` (which linearises at its operating point), run in pipe mode on the
same text; a hand-solved diode equation; finite differences for derivatives.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from netlistdyn.base.errors import NetlistError
from netlistdyn.circuit.netlist import Kind
from netlistdyn.devices.models import GMIN, Behaviour, diode_charge, diode_current, fold, thermal_voltage
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.formulation.nonlinear import NoOperatingPoint
from netlistdyn.formulation.operating import linearised, operating_point
from netlistdyn.frontend.parser import parse_text

from .conftest import NETLISTS

#: Agreement demanded with ngspice's .op: both solve the same equations with
#: Newton to rounding level (ngspice at reltol 1e-12); 1e-9 leaves room for
#: the conditioning of the node equations only. Currents are compared with a
#: floor of 1e-12 of the largest current: a branch current obtained from a
#: difference of node voltages is known only to ~eps·V·G absolutely.
OP_RTOL = 1e-9
#: Agreement with ngspice's .ac at its operating point (issue #14).
AC_RTOL = 1e-6

_MODEL = ".model dm D(IS=2.52n N=1.752 RS=0.568 CJO=4p M=0.4 TT=20n)\n"

CIRCUITS = {
    "rectifier": (
        "half-wave rectifier with RC load\n"
        + _MODEL
        + "V1 in 0 DC 0.8 AC 1\nD1 in out dm\nR1 out 0 1k\nC1 out 0 10u\n",
        "out",
    ),
    "clipper": (
        "diode clipper\n"
        + _MODEL
        + "V1 in 0 DC 1.3 AC 1\nR1 in out 470\nD1 out a dm\nV2 a 0 0.6\nD2 b out dm\nV3 b 0 -0.6\n"
        "C1 out 0 2.2n\nR2 out 0 10k\n",
        "out",
    ),
    "b-source RC": (
        "nonlinear RC from behavioural sources\n"
        "V1 in 0 DC 1.5 AC 1\nR1 in a 1k\nC1 a 0 1u\nB1 a 0 I={2m*v(a)**3 + 0.5m*tanh(v(a))}\n"
        "E1 b 0 value={v(a)*v(a) - 0.1*i(V1)*1k}\nR2 b c 100\nC2 c 0 100n\n"
        "G1 c 0 cur={1m*exp(v(c)/2) - 1m}\n",
        "c",
    ),
    "diode-RC ladder": (
        "diode-RC ladder, 6 stages\n"
        + _MODEL
        + "V1 n0 0 DC 3 AC 1\n"
        + "".join(f"R{k} n{k - 1} n{k} 1k\nD{k} n{k} 0 dm\nC{k} n{k} 0 1n\n" for k in range(1, 7)),
        "n6",
    ),
}

needs_ngspice = pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice is not installed")


def _ngspice(text: str, commands: list[str], tmp: Path) -> str:
    deck = tmp / "deck.cir"
    deck.write_text(text + ".options reltol=1e-12 abstol=1e-18 vntol=1e-15\n.end\n")
    script = "\n".join(["set numdgt=17", *commands, "quit", ""])
    proc = subprocess.run(
        ["ngspice", "-n", "-p", str(deck)], input=script.encode(), capture_output=True, timeout=30, cwd=tmp
    )
    return proc.stdout.decode("utf-8", "replace")


def _values(output: str) -> list[dict[str, complex]]:
    """Blocks of ``name = re[,im]`` lines, one per ``print all``."""
    blocks: list[dict[str, complex]] = []
    for line in output.splitlines():
        if line.strip() == "BLOCK":
            blocks.append({})
            continue
        match = re.match(r"^\s*(\S+) = ([-+0-9.eE]+)(?:,([-+0-9.eE]+))?\s*$", line)
        if match and blocks and match.group(1).lower() != "frequency":
            blocks[-1][match.group(1).lower()] = complex(float(match.group(2)), float(match.group(3) or 0.0))
    return [b for b in blocks if b]


@needs_ngspice
@pytest.mark.parametrize("name", list(CIRCUITS))
def test_operating_point_and_ac_against_ngspice(name: str, tmp_path: Path) -> None:
    text, out = CIRCUITS[name]
    freqs = (12.3, 4.56e3, 789e3)
    commands = ["op", "echo BLOCK", "print all"]
    commands += [c for f in freqs for c in (f"ac lin 1 {f} {f}", "echo BLOCK", "print all")]
    blocks = _values(_ngspice(text, commands, tmp_path))
    assert len(blocks) == 1 + len(freqs)
    ref_op = blocks[0]
    netlist = parse_text(text + ".end\n")
    point = operating_point(netlist)
    assert point.residual < 1e-12
    for node, value in point.voltages.items():
        if "#" in node:
            continue
        ref = ref_op[node].real
        assert abs(value - ref) <= OP_RTOL * abs(ref) + 1e-15, (node, value, ref)
    # ngspice names an E/G with value= "be1"/"bg1" (a B source); a current-type B has no branch current
    currents = {
        re.sub(r"^be", "e", k[: -len("#branch")]): v.real
        for k, v in ref_op.items()
        if k.endswith("#branch") and not k.startswith("bg")
    }
    scale = max(abs(v) for v in currents.values())
    for key, ref in currents.items():
        ours = point.currents[key]
        assert abs(ours - ref) <= OP_RTOL * abs(ref) + 1e-12 * scale, (key, ours, ref)
    # ngspice's .ac linearises at its operating point: the same transfer function as A, B, C, D
    model = compile_netlist(netlist, [f"v({out})"])
    j = model.inputs.index("V1")
    for f, block in zip(freqs, blocks[1:], strict=True):
        ours = complex(model.transfer_function(2j * math.pi * f)[0, j])
        ref = block[out]
        assert abs(ours - ref) <= AC_RTOL * abs(ref), (f, ours, ref)


def test_diode_equation_closed_form() -> None:
    """A diode fed by a current source: V = n Vt ln(1 + (I - gmin V)/Is), solved by bisection here."""
    text = ".model dx D(IS=1e-14 N=1.3)\nI1 0 a 2m\nD1 a 0 dx\n.end\n"
    point = operating_point(parse_text("t\n" + text))
    vte = 1.3 * thermal_voltage()
    lo, hi = 0.0, 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if 1e-14 * math.expm1(mid / vte) + GMIN * mid > 2e-3:
            hi = mid
        else:
            lo = mid
    assert abs(point.voltages["a"] - lo) <= 1e-13 * lo


def test_diode_derivatives_match_finite_differences() -> None:
    for vd in (-5.0, -0.1, 0.0, 0.3, 0.45, 0.7):
        i, g = diode_current(vd, 1e-12, 1.5)
        h = 1e-7
        fd = (diode_current(vd + h, 1e-12, 1.5)[0] - diode_current(vd - h, 1e-12, 1.5)[0]) / (2 * h)
        assert abs(g - fd) <= 1e-6 * abs(g)
        _, c = diode_charge(vd, i, g, 5e-12, 0.8, 0.33, 1e-9, 0.5)
        ip, gp = diode_current(vd + h, 1e-12, 1.5)
        im, gm = diode_current(vd - h, 1e-12, 1.5)
        fdq = (
            diode_charge(vd + h, ip, gp, 5e-12, 0.8, 0.33, 1e-9, 0.5)[0]
            - diode_charge(vd - h, im, gm, 5e-12, 0.8, 0.33, 1e-9, 0.5)[0]
        ) / (2 * h)
        assert abs(c - fdq) <= 1e-6 * abs(c)


def test_behaviour_gradient_matches_finite_differences() -> None:
    text = fold(
        "k*v(a)**2.5 + pwr(v(a,b), 3) / (1 + exp(v(b))) + sin(time*w) * i(V1) + max(v(a), 0.3*v(b))",
        {"k": 2.0, "w": 100.0},
        {},
    )
    b = Behaviour.from_text(text)
    assert [k for k, _ in b.variables] == ["v", "v", "time", "i"]
    x = np.array([0.7, -0.4, 1e-3, 2e-3])
    _, grad = b.evaluate(x)
    for k in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[k]))
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fd = (b.evaluate(xp)[0] - b.evaluate(xm)[0]) / (2 * h)
        assert abs(grad[k] - fd) <= 1e-6 * max(1.0, abs(fd))


def test_linear_netlists_are_untouched() -> None:
    netlist = parse_text("t\nV1 a 0 1\nR1 a b 1k\nC1 b 0 1u\nB1 c 0 V={2*v(b)}\nR2 c 0 1k\n.end\n")
    assert not netlist.is_nonlinear
    assert {e.kind for e in netlist.elements} <= {Kind.VSOURCE, Kind.RESISTOR, Kind.CAPACITOR, Kind.VCVS}


def test_linearisation_names_states_and_at() -> None:
    text = CIRCUITS["rectifier"][0] + ".end\n"
    netlist = parse_text(text)
    _, outputs = linearised(netlist)
    assert outputs == ["v(in)", "v(out)"]
    model = compile_netlist(netlist)
    assert model.states == ("q(D1)", "q(C1)")
    # reverse bias through --at: the diode is a tiny conductance, the output almost decoupled
    reverse = compile_netlist(linearised(netlist, at={"V1": -2.0})[0], outputs)
    assert abs(reverse.transfer_function(0.0)[1, 0]) < 1e-6


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("D1 a 0 nomodel\n", "no .model nomodel"),
        (".model dq D(IS=1e-14 CJSW=5p)\nD1 a 0 dq\n", "CJSW"),
        (".model dq NPN(IS=1e-14)\nD1 a 0 dq\n", "not D"),
        ("B1 a 0 V={v(zz)**2}\n", "v(zz) names no node"),
        ("B1 a 0 I={exp(v(a)) * foo}\n", "unknown parameter 'foo'"),
        ("B1 a 0 I={i(R9)*v(a)**2}\n", "i(r9) names no element"),
        ("B1 a 0 I={bogus(v(a))}\n", "unknown function 'bogus'"),
        (".model dq D(IS=-1)\nD1 a 0 dq\n", "IS and N must be positive"),
    ],
)
def test_bad_inputs_one_line(body: str, message: str) -> None:
    assert_one_line_error("t\nV1 a 0 1\nR1 a 0 1k\n" + body + ".end\n", message)


def assert_one_line_error(text: str, message: str) -> None:
    """Compiling ``text`` fails with one line ``bad.cir:N: ...`` containing ``message``."""
    with pytest.raises(NetlistError) as info:
        compile_netlist(parse_text(text, "bad.cir"))
    assert message in str(info.value)
    assert str(info.value).startswith("bad.cir:")
    assert "\n" not in str(info.value)


def test_no_operating_point_is_reported() -> None:
    # a current source into a node whose only path is a B source that can carry at most 1 mA
    text = "t\nI1 0 a 2m\nB1 a 0 I={1m*tanh(v(a))}\n.end\n"
    with pytest.raises(NoOperatingPoint, match="no operating point"):
        operating_point(parse_text(text))


# ------------------------------------------------------------------ nonlinear transient

#: Transient agreement with ngspice (issue #14): max error over the run relative to the peak.
TRAN_RTOL = 1e-4

#: The example netlists of netlists/ (a .tran each) and the outputs compared.
TRANSIENTS = {
    "rectifier": ("rectifier.cir", ["v(out)"]),
    "clipper": ("clipper.cir", ["v(out)"]),
    "b-source RC": ("nonlinear_rc.cir", ["v(a)", "v(c)"]),
    "diode-RC ladder": ("diode_ladder.cir", ["v(n1)", "v(n4)"]),
}


#: ngspice's settings as a reference: Gear, tight tolerances (a small maximum step is set below).
TRAN_OPTIONS = "reltol=1e-7 abstol=1e-14 vntol=1e-10 chgtol=1e-20 method=gear"


def _ngspice_tran(
    text: str, tstop: float, outputs: list[str], tmp: Path, options: str = TRAN_OPTIONS
) -> np.ndarray:
    deck = tmp / "tran.cir"
    # from zero (uic), with a maximum step of tstop/20000
    deck.write_text(text + f".options {options}\n.end\n")
    data = tmp / "tran.txt"
    script = "\n".join(
        [
            f"tran {tstop / 200:g} {tstop:g} 0 {tstop / 20000:g} uic",
            f"linearize {' '.join(outputs)}",
            f"wrdata {data} {' '.join(outputs)}",
            "quit",
            "",
        ]
    )
    subprocess.run(
        ["ngspice", "-n", "-p", str(deck)], input=script.encode(), capture_output=True, timeout=60, cwd=tmp
    )
    table = np.loadtxt(data)
    return np.column_stack([table[:, 0]] + [table[:, 2 * k + 1] for k in range(len(outputs))])


@needs_ngspice
@pytest.mark.parametrize("name", list(TRANSIENTS))
def test_transient_against_ngspice(name: str, tmp_path: Path) -> None:
    file, outputs = TRANSIENTS[name]
    lines = (NETLISTS / file).read_text().splitlines(keepends=True)
    text = "".join(line for line in lines if line.strip().lower() != ".end")
    tran = parse_text(text + ".end\n").tran
    assert tran is not None
    assert_transient_matches(text, tran.tstop, outputs, tmp_path)


def assert_transient_matches(
    text: str, tstop: float, outputs: list[str], tmp: Path, options: str = TRAN_OPTIONS
) -> None:
    """The nonlinear transient (rtol 1e-6) within TRAN_RTOL of each output's peak of ngspice's."""
    from netlistdyn.simulation.nltransient import run

    ref = _ngspice_tran(text, tstop, outputs, tmp, options)
    ours = run(parse_text(text + ".end\n"), outputs, ref[:, 0], rtol=1e-6)
    for k, out in enumerate(outputs):
        peak = np.abs(ref[:, k + 1]).max()
        err = np.abs(ours.outputs[:, k] - ref[:, k + 1]).max()
        assert err <= TRAN_RTOL * peak, (out, err / peak)


def test_validate_nonlinear_netlist() -> None:
    """validate: ngspice on netlistdyn's reading (diode, B source) against the nonlinear transient."""
    pytest.importorskip("PySpice")
    if shutil.which("ngspice") is None:
        pytest.skip("ngspice is not installed")
    import netlistdyn

    # a diode without junction capacitance: the time scales are the RC's (a short ngspice run)
    text = (
        "rectifier\n.model dz D(IS=1e-14 N=1.2 RS=2)\nV1 in 0 SIN(0 5 1k)\nD1 in out dz\nR1 out 0 1k\n"
        "C1 out 0 1u\nB1 b 0 V={0.1*v(out)**2}\nR2 b 0 1k\n.end\n"
    )
    check = netlistdyn.validate(text, tstop="0.5m", tstep="5u", pz=False)
    assert check.passed
    worst = max(c.max_rel_error for c in check.report.comparisons)
    assert worst <= TRAN_RTOL


def test_held_charge_reports_the_drift() -> None:
    """op --at q(C1)=0.2u: v(a) = 0.2 V, the inductor's current settles (di/dt = 0: i = v(a)/R2) and
    dq/dt = (1 − 0.2)/1k − 0.2/1k − Is (exp(0.2/Vt) − 1) − gmin·0.2 is reported as the drift."""
    text = (
        "t\n.model dm D(IS=1e-14)\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u\nD1 a 0 dm\nL1 a b 1m\nR2 b 0 1k\n.end\n"
    )
    point = operating_point(parse_text(text), {"q(C1)": 0.2e-6})
    assert abs(point.voltages["a"] - 0.2) <= 1e-12
    vt = 1.38064852e-23 * 300.15 / 1.6021766208e-19
    expected = 0.8e-3 - 0.2e-3 - 1e-14 * math.expm1(0.2 / vt) - GMIN * 0.2
    assert set(point.drift) == {"q(C1)"}
    assert abs(point.drift["q(C1)"] - expected) <= 1e-9 * expected
    assert abs(point.currents["l1"] - 0.2e-3) <= 1e-12


def test_omitted_pulse_times_take_spice_defaults() -> None:
    """PULSE(0 3 1u) is PULSE(0 3 1u TSTEP TSTEP TSTOP TSTOP), as ngspice resolves it (was a TypeError)."""
    from netlistdyn.simulation.nltransient import run

    body = "V1 a 0 PULSE(0 3 1u{})\nR1 a b 1k\nD1 b 0 dm\nC1 b 0 1n\n" + _MODEL
    times = np.linspace(0.0, 20e-6, 101)  # TSTEP = 0.2 us, TSTOP = 20 us
    short = run(parse_text("short\n" + body.format("") + ".end\n"), ["v(b)"], times, rtol=1e-6)
    full = run(
        parse_text("full\n" + body.format(" 0.2u 0.2u 20u 20u") + ".end\n"), ["v(b)"], times, rtol=1e-6
    )
    assert np.abs(short.outputs).max() > 0.5  # the pulse did rise
    # the same equations and inputs, so the same steps: equal to rounding of the peak
    assert np.abs(short.outputs - full.outputs).max() <= 1e-12 * np.abs(full.outputs).max()
    held = operating_point(parse_text("held\n" + body.format("") + ".end\n"), {"q(C1)": 1e-9})
    assert "q(C1)" in held.drift  # a charge held away from equilibrium moves (no crash)


def test_junction_capacitance_loop_is_refused_in_one_line() -> None:
    """A diode's junction charge (no RS) across a capacitor: a capacitor loop, refused (was LinAlgError)."""
    from netlistdyn.simulation.nltransient import run

    text = "loop\nV1 a 0 PULSE(0 3 1u 0.2u 0.2u 20u 20u)\nR1 a b 1k\nD1 b 0 dm\nC1 b 0 1n\n"
    text += ".model dm D(IS=2.52n N=1.752 CJO=4p)\n.end\n"
    with pytest.raises(NetlistError, match="no solution"):
        run(parse_text(text), ["v(b)"], np.linspace(0.0, 20e-6, 11), rtol=1e-6)
