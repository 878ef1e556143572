"""ngspice's level-1 diode, parameter by parameter, judged against ``ngspice -b`` (issue #27).

Vendor models (1N4148, 1N4007, a zener with recombination current) and one probe per parameter
(BV/IBV/NBV breakdown, IKF/IKR knees, ISR/NR recombination, EG/XTI/TNOM and the circuit
temperature, M= with breakdown): the operating point, the small-signal model's transfer function
against ngspice's ``.ac`` at three frequencies, and a transient.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest

from netlistdyn.base.errors import NetlistError
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.formulation.operating import operating_point
from netlistdyn.frontend.parser import parse_text

from .test_nonlinear import _ngspice, _values, assert_transient_matches

pytestmark = pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice is not installed")

#: Operating point against ngspice at reltol 1e-12 (its Newton to rounding, as ours): 1e-9 of each
#: node voltage (the acceptance asks 1e-6 of the largest). Branch currents are not compared: where
#: a junction blocks, the current is a difference of node voltages that ngspice converges only to
#: reltol·|v| (2.6e-8 of a 2.5 nA reverse current, measured).
OP_RTOL = 1e-9
#: Small-signal transfer values against ngspice's .ac at its operating point: 1e-7 (both linearise
#: the same equations at operating points equal to 1e-9; measured 1e-10 and below).
AC_RTOL = 1e-7

D1N4148 = ".model D1N4148 D(IS=2.52n N=1.752 RS=0.568 CJO=4p M=0.4 TT=20n BV=100)\n"
D1N4007 = (
    ".model D1N4007 D(IS=7.02767n RS=0.0341512 N=1.80803 EG=1.05743 XTI=5 BV=1000 IBV=0.1 CJO=1e-11"
    " VJ=0.7 M=0.5 FC=0.5 TT=1e-7 KF=0 AF=1)\n"
)
ZENER = (
    ".model DZ D(IS=1.085f RS=1.21 IKF=0 N=1 XTI=3 EG=1.11 CJO=148p M=.3407 VJ=.75 FC=.5 ISR=2.418n"
    " NR=2 BV=5.1 IBV=49.06m NBV=1.1)\n"
)

# name: (netlist text without .end, output node for .ac)
CIRCUITS: dict[str, tuple[str, str]] = {
    "1n4148_forward": ("f\n" + D1N4148 + "V1 in 0 DC 5 AC 1\nR1 in a 1k\nD1 a 0 D1N4148\n", "a"),
    "1n4148_reverse": ("r\n" + D1N4148 + "V1 in 0 DC -20 AC 1\nR1 in a 1k\nD1 a 0 D1N4148\n", "a"),
    "1n4148_breakdown": ("b\n" + D1N4148 + "V1 in 0 DC -101 AC 1\nR1 in a 10k\nD1 a 0 D1N4148\n", "a"),
    "1n4007_forward": ("f\n" + D1N4007 + "V1 in 0 DC 3 AC 1\nR1 in a 10\nD1 a 0 D1N4007\n", "a"),
    "zener_breakdown": ("z\n" + ZENER + "V1 in 0 DC -12 AC 1\nR1 in a 1k\nD1 a 0 DZ\nC1 a 0 10n\n", "a"),
    "zener_recombination": ("z\n" + ZENER + "V1 in 0 DC 0.6 AC 1\nR1 in a 10\nD1 a 0 DZ\n", "a"),
    "knee_ikf": (
        "k\n.model DK D(IS=1e-12 N=1.5 IKF=1m RS=1 CJO=2p TT=5n)\n"
        "V1 in 0 DC 2 AC 1\nR1 in a 100\nD1 a 0 DK\n",
        "a",
    ),
    "knee_ikr_breakdown": (
        "k\n.model DK D(IS=1e-9 N=1.2 IKR=2m BV=10 IBV=1m)\nV1 in 0 DC -15 AC 1\nR1 in a 1k\nD1 a 0 DK\n",
        "a",
    ),
    "nbv_ibv_multiplier": (
        "m\n.model DB D(IS=1e-12 BV=8 IBV=1u NBV=3 CJO=1p)\nV1 in 0 DC -12 AC 1\nR1 in a 1k\n"
        "D1 a 0 DB area=2 m=3\n",
        "a",
    ),
    "temp_1n4007": ("t\n" + D1N4007 + ".temp 75\nV1 in 0 DC 3 AC 1\nR1 in a 10\nD1 a 0 D1N4007\n", "a"),
    "temp_cold_breakdown": (
        "t\n" + D1N4148 + ".options temp=-20\nV1 in 0 DC -110 AC 1\nR1 in a 10k\nD1 a 0 D1N4148\n",
        "a",
    ),
    "tnom_and_options_tnom": (
        "t\n.model DT D(IS=1e-13 N=1.1 CJO=3p VJ=0.6 M=0.45 TNOM=50 EG=1.2 XTI=2)\n"
        ".model DU D(IS=1e-13 CJO=3p ISR=1n NR=2.5)\n.options tnom=10\n.temp 40\n"
        "V1 in 0 DC 1.5 AC 1\nR1 in a 1k\nD1 a b DT\nD2 b 0 DU\nR2 b 0 10k\n",
        "b",
    ),
    "instance_temp": (
        "t\n" + D1N4007 + "V1 in 0 DC 3 AC 1\nR1 in a 10\n"
        "D1 a b D1N4007 temp=100\nD2 b 0 D1N4007 dtemp=-30\n",
        "b",
    ),
}


@pytest.mark.parametrize("name", list(CIRCUITS))
def test_operating_point_and_ac(name: str, tmp_path: Path) -> None:
    text, out = CIRCUITS[name]
    freqs = (12.3, 4.56e3, 789e3)
    # one ngspice session per analysis: ngspice 39 applies a diode's M= once more at each further
    # analysis of a session (op then ac: the area times M twice; measured, not in its netlist)
    runs = [["op"]] + [[f"ac lin 1 {f} {f}"] for f in freqs]
    blocks = [_values(_ngspice(text, [*run, "echo BLOCK", "print all"], tmp_path))[0] for run in runs]
    netlist = parse_text(text + ".end\n")
    point = operating_point(netlist)
    for node, value in point.voltages.items():
        if "#" in node:
            continue
        ref = blocks[0][node].real
        assert abs(value - ref) <= OP_RTOL * abs(ref) + 1e-12, (node, value, ref)
    model = compile_netlist(netlist, [f"v({out})"])
    j = model.inputs.index("V1")
    for f, block in zip(freqs, blocks[1:], strict=True):
        ours = complex(model.transfer_function(2j * math.pi * f)[0, j])
        ref = block[out]
        assert abs(ours - ref) <= AC_RTOL * abs(ref), (f, ours, ref)


#: Transients of a rectifier and a zener clamp (the nonlinear transient at rtol 1e-6 against Gear at
#: reltol 1e-7): 1e-4 of each output's peak, test_nonlinear's TRAN_RTOL.
TRANSIENTS = {
    "1n4007_rectifier": (
        "r\n" + D1N4007 + "V1 in 0 SIN(0 10 1k)\nD1 in out D1N4007\nR1 out 0 1k\nC1 out 0 2u\n",
        3e-3,
    ),
    "zener_clamp_warm": (
        "z\n"
        + ZENER
        + ".temp 60\nV1 in 0 SIN(0 9 1k)\nR1 in a 500\nD1 0 a DZ\nD2 b a D1N4148\nR2 b 0 1k\n"
        + D1N4148,
        2e-3,
    ),
}


@pytest.mark.parametrize("name", list(TRANSIENTS))
def test_transient(name: str, tmp_path: Path) -> None:
    text, tstop = TRANSIENTS[name]
    netlist = parse_text(text + ".end\n")
    outputs = [f"v({n})" for n in netlist.nodes if n != "in"]
    assert_transient_matches(text, tstop, outputs, tmp_path)


@pytest.mark.parametrize(
    ("card", "message"),
    [
        ("CJSW=1p", "CJSW: ngspice's diode parameter is not supported"),
        ("TLEV=1", "TLEV: ngspice's diode parameter is not supported"),
        ("LEVEL=3", "LEVEL: only the default 1 is supported"),
        ("BV=-5", "BV, IBV and NBV must be positive"),
    ],
)
def test_unsupported_parameters_are_refused_by_name(card: str, message: str) -> None:
    text = f"d\n.model dx D(IS=1e-14 {card})\nV1 a 0 1\nR1 a b 1k\nD1 b 0 dx\n.end\n"
    with pytest.raises(NetlistError) as info:
        parse_text(text)
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_noise_and_unknown_parameters_are_ignored_as_ngspice_ignores_them() -> None:
    """KF/AF (noise) change nothing; IBVL (PSpice's, unknown to ngspice 39) is ignored with a warning."""
    base = "d\n.model dx D(IS=1e-14 {})\nV1 a 0 1\nR1 a b 1k\nD1 b 0 dx\n.end\n"
    plain = operating_point(parse_text(base.format(""))).voltages["b"]
    noisy = parse_text(base.format("KF=1e-16 AF=1.2 IBVL=1m"))
    assert operating_point(noisy).voltages["b"] == pytest.approx(plain, rel=0, abs=0)
    assert [w.message for w in noisy.warnings] == [
        ".model dx IBVL: not a diode parameter: ignored, as ngspice 39 does"
    ]
