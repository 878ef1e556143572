"""Independent-source forms judged against ``ngspice -b`` on the same text (issue #27).

* The operating point of a source written without a DC value is its waveform's value at t = 0
  (ngspice 39's ``vsrcload``: ``.op`` loads the transient function at time 0 when no DC value was
  given), for every form: SIN (6 and KiCad's 7 values), PULSE (7 and 8 values), EXP, PWL, SFFM,
  AM, with and without a DC value, into a divider and into a diode.
* Transients of the forms added here (SIN with 7 values, AM, SFFM, PULSE with an eighth value, a
  PULSE whose TR + PW + TF exceeds PER) against a tight ngspice run.
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

import netlistdyn
from netlistdyn.base.errors import NetlistError
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.formulation.operating import operating_point
from netlistdyn.frontend.parser import parse_text

from .ngspice_probe import NGSPICE, ngspice_op

pytestmark = pytest.mark.skipif(NGSPICE is None, reason="ngspice is not installed")

#: Operating points: a linear solve (divider) or Newton to rounding (diode), against ngspice
#: printing 15 digits at reltol 1e-12: 1e-9 of the value, 1e-12 V absolute (ngspice's gmin 1e-12 S
#: across the diode moves its node by ~1e-13 V here).
OP_RTOL = 1e-9
OP_ATOL = 1e-12

FORMS = {
    "sin_no_dc": "SIN(0.5 0.5 120)",
    "sin_phase": "SIN(0.2 1 200 0 0 30)",
    "sin_kicad_7": "SIN( 0.2 1 200 0 0 30 45 )",
    "sin_delayed_phase": "SIN(0.1 0.3 1k 1m 10 60)",
    "sin_with_dc": "DC 1 SIN(0.5 0.5 120)",
    "pulse": "PULSE(0.3 1 1m 1m 1m 1m 4m)",
    "pulse_8": "PULSE(0.3 1 0 1m 1m 1m 4m 2)",
    "pulse_with_dc": "0.8 PULSE(0.3 1 1m 1m 1m 1m 4m)",
    "exp": "EXP(0.7 1 1m 1m)",
    "pwl_at_zero": "PWL(0 0.4 1m 1)",
    "pwl_later": "PWL(1m 0.4 2m 1)",
    "pwl_td": "PWL(0 0.6 1m 1) TD=1m",
    "sffm": "SFFM(0.1 1 1k 2 100)",
    "sffm_phases": "SFFM(0.1 1 1k 2 100 30 60)",
    "am": "AM(1 0.5 100 1k 0)",
    "am_delayed": "AM(1 0.5 100 1k 1m 30 60)",
    "am_with_dc": "DC 0.4 AM(1 0.5 100 1k 0)",
}
CIRCUITS = {
    "divider": "Vin 1 0 {}\nR1 1 2 300\nR2 2 0 300\n",
    "diode": "Vin 1 0 {}\nR1 1 2 300\nR2 2 0 300\nD1 2 0 dm\n.model dm D(IS=1e-9 N=1.5)\n",
}


@pytest.mark.parametrize("circuit", list(CIRCUITS))
@pytest.mark.parametrize("form", list(FORMS))
def test_operating_point_takes_the_waveform_at_t0(form: str, circuit: str) -> None:
    """``op`` (and so ``analyze``'s linearisation point) as ngspice's ``.op`` of the same file."""
    text = "op probe\n" + CIRCUITS[circuit].format(FORMS[form])
    theirs = ngspice_op(text + ".options reltol=1e-12 abstol=1e-18 vntol=1e-15\n")
    point = operating_point(parse_text(text + ".end\n"))
    for node in ("1", "2"):
        ours, ref = point.voltages[node], theirs[f"v({node})"]
        assert abs(ours - ref) <= OP_RTOL * abs(ref) + OP_ATOL, (node, ours, ref)


def ngspice_tran(text: str, tstep: float, tstop: float, output: str) -> tuple[np.ndarray, np.ndarray]:
    """ngspice's transient (the ``.tran`` of ``text``) at tight tolerances, linearised onto a TSTEP grid."""
    assert NGSPICE is not None
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "out.txt"
        deck = (
            f"{text}.options reltol=1e-9 abstol=1e-15 vntol=1e-12\n"
            f".control\nrun\nlinearize {output}\nwrdata {data} {output}\n.endc\n.end\n"
        )
        (Path(tmp) / "t.cir").write_text(deck)
        subprocess.run([NGSPICE, "-b", "t.cir"], capture_output=True, text=True, timeout=120, cwd=tmp)
        table = np.loadtxt(data, ndmin=2)
    return table[:, 0], table[:, 1]


#: Transients of an RC (τ = 1 ms) against ngspice (trapezoidal, reltol 1e-9, at most TSTEP/100):
#: 1e-5 of the output's peak (measured 2e-6 at most: ngspice steps over the jumps of a cut PULSE
#: and of AM at TD, 1.5e-5 at TSTEP/10, converging to ours as its step shrinks;
#: the PULSE cut at PER differed by 1.7e-4 before ngspice's period handling was followed).
TRAN_RTOL = 1e-5
RC = "Vin in 0 {}\nR1 in out 1k\nC1 out 0 1u\n"
TRANSIENTS = {
    "sin_kicad_7": (RC.format("SIN( 0.2 1 200 0 0 30 45 )"), 1e-5, 20e-3),
    "sin_no_dc_start": (RC.format("SIN(0.5 0.5 120)"), 1e-5, 20e-3),
    "am": (RC.format("AM(2 1 50 500)"), 1e-5, 20e-3),
    "am_delayed_phases": (RC.format("AM(1 0.5 100 1k 1m 30 60)"), 1e-5, 20e-3),
    "sffm": (RC.format("SFFM(0.1 1 1k 2 100 30 60)"), 1e-5, 20e-3),
    "pulse_ncycles": (RC.format("PULSE(0 1 0 1m 1m 1m 4m 2)"), 1e-5, 20e-3),
    "pulse_ncycles_fraction": (RC.format("PULSE(0 1 0 1m 1m 1m 4m 2.5)"), 1e-5, 20e-3),
    # issue #27: TR + PW + TF > PER: each period is cut at PER and starts again at V1
    "pulse_longer_than_period": (
        "Vin in 0 PULSE(0 25 1u 1u 1u 1 1)\nR1 in out 1.2meg\nC1 out 0 20u\n",
        1e-3,
        3.0,
    ),
    "pulse_cut_short_period": (RC.format("PULSE(0 1 0.2m 1m 1m 1m 2.5m)"), 1e-5, 20e-3),
}


@pytest.mark.parametrize("name", list(TRANSIENTS))
def test_transient_against_ngspice(name: str) -> None:
    body, tstep, tstop = TRANSIENTS[name]
    text = f"tran probe\n{body}.tran {tstep!r} {tstop!r} 0 {tstep / 100!r}\n"
    t, ref = ngspice_tran(text, tstep, tstop, "v(out)")
    result = netlistdyn.simulate(text + ".end\n", outputs=["v(out)"], tstop=tstop, tstep=tstep)
    ours = np.interp(t, result.time, result.values[:, 0])
    err = np.abs(ours - ref).max() / np.abs(ref).max()
    assert err <= TRAN_RTOL, err


# --- M= on a subcircuit instance ---------------------------------------------------------------

#: A subcircuit with every element kind an instance multiplier meets: R, L divided, C (and
#: C={...}), G, F, I and a diode's area multiplied, V, E, H, B, K left alone (ngspice 39).
MULTIPLIED = (
    "m\n.model dd D(IS=1e-12 CJO=2p BV=3 IBV=1m)\n"
    ".subckt cell a b\nR1 a n1 1k\nC1 n1 b 1u\nL1 n1 n2 1m\nR2 n2 b 2k\nG1 a b n1 b 0.1m\n"
    "Vs n2 n3 0\nR3 n3 b 3k\nF1 n1 b Vs 0.5\nH1 n4 b Vs 200\nR4 a n4 5k\nE1 n5 b n1 b 0.5\nR5 a n5 4k\n"
    "I1 a b 0.1m\nD1 n1 b dd\nB1 n1 b I={0.1m*v(n1,b)}\nC2 n2 b C={2u}\n.ends\n"
    ".subckt outer a b\nX1 a b cell m=2\nR7 a b 20k\n.ends\n"
    "V1 in 0 DC 1 AC 1\nRs in x 100\nXX x 0 cell M = 10\nRt in y 200\nXY y 0 outer m={1.5*2}\n"
)


def test_subcircuit_instance_multiplier(tmp_path: Path) -> None:
    """``XX x 0 cell M = 10``: op and .ac of every node as ngspice's, nested multipliers compose."""
    from .test_nonlinear import _ngspice, _values

    netlist = parse_text(MULTIPLIED + ".end\n")
    point = operating_point(netlist)
    blocks = [
        _values(_ngspice(MULTIPLIED, [run, "echo BLOCK", "print all"], tmp_path))[0]
        for run in ("op", "ac lin 1 1.5k 1.5k")
    ]
    nodes = [n for n in netlist.nodes if n in blocks[0]]
    assert len(nodes) >= 12, nodes
    for node in nodes:
        ours, ref = point.voltages[node], blocks[0][node].real
        assert abs(ours - ref) <= OP_RTOL * abs(ref) + OP_ATOL, (node, ours, ref)
    model = compile_netlist(netlist, [f"v({n})" for n in nodes])
    h = model.transfer_function(2j * np.pi * 1.5e3)[:, model.inputs.index("V1")]
    for k, node in enumerate(nodes):
        ref = blocks[1][node]
        assert abs(complex(h[k]) - ref) <= 1e-7 * abs(ref) + 1e-12, (node, complex(h[k]), ref)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("L1 a b 1m\nL2 c b 1m\nR1 c b 1\nK1 L1 L2 0.5\n", "K1 (COUPLING) is not supported"),
        ("R1 a b 1k m=2\n", "R1: m= on an element inside a subcircuit instance that has m="),
    ],
)
def test_subcircuit_multiplier_refusals(body: str, message: str) -> None:
    text = f"m\n.subckt cell a b\n{body}.ends\nV1 in 0 1\nR0 in x 1k\nX1 x 0 cell m=3\n.end\n"
    with pytest.raises(NetlistError) as info:
        parse_text(text)
    assert message in str(info.value)
    assert "\n" not in str(info.value)
