"""Nonlinear capacitors and inductors (issue #14): ``C={expr}``, ``Q={expr}``, ``L={expr}``.

ngspice 39 reads ``C={C(v)}`` as i = C(v)·dv/dt, ``Q={Q(v)}`` as i = dQ(v)/dt
and ``L={L(i)}`` as v = L(i)·di/dt, the inductor's current read through a
voltage source in series (measured with ``ngspice -b``: a 1 mA step into
C = 1n·(1 + v) reaches 0.4142132 V at 0.5 µs, √(1 + 2·0.5) − 1 = 0.41421356;
the charge reading C(v)·v would give 0.366). References: ngspice's own
``.op``, ``.ac`` and ``.tran`` on the same text, and closed forms.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from netlistdyn.circuit.netlist import Kind
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.formulation.operating import operating_point
from netlistdyn.frontend.parser import parse_text
from netlistdyn.simulation.nltransient import run
from tests.test_nonlinear import (
    AC_RTOL,
    OP_RTOL,
    TRAN_RTOL,
    _ngspice,
    _values,
    assert_one_line_error,
    assert_transient_matches,
    needs_ngspice,
)

#: One circuit with each form: C= on a grounded node, Q= on a floating pair read as v(b,c),
#: L= reading the current of the 0 V source Vm in series.
CIRCUIT = (
    "nonlinear C and L\n"
    "V1 in 0 {src}\n"
    "R1 in a 1k\nC1 a 0 C={{1n*(1+0.5*v(a)**2)}}\nR2 a 0 3k\n"
    "R3 in b 1k\nC2 b c Q={{1n*(v(b,c)+v(b,c)**3/3)}}\nR4 c 0 2k\nR5 b 0 5k\n"
    "Vm in d 0\nL1 d e L={{1m/(1+(i(Vm)/3m)**2)}}\nR6 e 0 1k\nC3 e 0 2n\n"
)
NODES = ("a", "b", "c", "e")

#: Closed forms: a step into each element alone. The sources rise in 1 ps (a PULSE), so the
#: exact solution is taken from t − 0.5 ps; what is left is the integrator's (rtol 1e-9).
CLOSED_RTOL = 1e-9


def test_parsed_as_nonlinear_storage() -> None:
    netlist = parse_text(CIRCUIT.format(src="DC 2") + ".end\n")
    kinds = {e.name: e.kind for e in netlist.elements}
    assert (kinds["C1"], kinds["C2"], kinds["L1"], kinds["C3"]) == (
        Kind.CAPACITANCE,
        Kind.CHARGE,
        Kind.INDUCTANCE,
        Kind.CAPACITOR,
    )
    assert netlist.is_nonlinear


@needs_ngspice
def test_op_and_ac_against_ngspice(tmp_path: Path) -> None:
    text = CIRCUIT.format(src="DC 2 AC 1")
    freqs = (1.3e3, 100e3, 2.1e6)
    commands = ["op", "echo BLOCK", "print all"]
    commands += [c for f in freqs for c in (f"ac lin 1 {f} {f}", "echo BLOCK", "print all")]
    blocks = _values(_ngspice(text, commands, tmp_path))
    assert len(blocks) == 1 + len(freqs)
    netlist = parse_text(text + ".end\n")
    point = operating_point(netlist)
    for node in NODES:
        ref = blocks[0][node].real
        assert abs(point.voltages[node] - ref) <= OP_RTOL * abs(ref) + 1e-15, node
    ref_i = blocks[0]["vm#branch"].real
    assert abs(point.currents["vm"] - ref_i) <= OP_RTOL * abs(ref_i)
    # the linearisation: incremental C(v0) = dq/dv, L(i0); its states are the charges and the current
    model = compile_netlist(netlist, [f"v({n})" for n in NODES])
    assert {"q(C1)", "q(C2)", "i(L1)"} <= set(model.states)
    j = model.inputs.index("V1")
    for f, block in zip(freqs, blocks[1:], strict=True):
        h = model.transfer_function(2j * math.pi * f)[:, j]
        for k, node in enumerate(NODES):
            ref = block[node]
            assert abs(complex(h[k]) - ref) <= AC_RTOL * abs(ref), (f, node, complex(h[k]), ref)


@needs_ngspice
def test_transient_against_ngspice(tmp_path: Path) -> None:
    text = CIRCUIT.format(src="PULSE(0 2 0.5u 0.2u 0.2u 3u 10u)")
    outputs = [f"v({n})" for n in NODES] + ["i(Vm)"]
    # ngspice's translation of C=/L= (unit-capacitor and unit-inductor auxiliaries, B sources) stops with
    # "timestep too small" at abstol 1e-14/vntol 1e-10: its default abstol (1 pA) and vntol (1 µV) here
    assert_transient_matches(text, 8e-6, outputs, tmp_path, options="reltol=1e-7 chgtol=1e-20 method=gear")


def test_steps_against_closed_forms() -> None:
    # 1 mA into C = 1n(1 + v): 1n (v + v²/2) = I t; into Q = 1n(v + v²/2): the same;
    # 1 V across L = 1m(1 − i) with Vm reversed (i(Vm) = −i(L1)): 1m (i + i²/2) = t
    text = (
        "steps\nI1 0 a PULSE(0 1m 0 1p 1p 1 2)\nC1 a 0 C={1e-9*(1+v(a))}\n"
        "I2 0 z PULSE(0 1m 0 1p 1p 1 2)\nC2 z 0 Q={1e-9*(v(z)+v(z)*v(z)/2)}\n"
        "Vs x 0 PULSE(0 1 0 1p 1p 1 2)\nVm y x 0\nL1 y 0 L={1e-3*(1-i(Vm))}\n.end\n"
    )
    t = np.linspace(0.0, 1e-6, 11)
    result = run(parse_text(text), ["v(a)", "v(z)", "i(L1)"], t, rtol=1e-9)
    te = np.maximum(t - 0.5e-12, 0.0)
    v = np.sqrt(1.0 + 2.0 * 1e-3 * te / 1e-9) - 1.0
    i = np.sqrt(1.0 + 2.0 * te / 1e-3) - 1.0
    for k, exact in enumerate((v, v, i)):
        assert np.abs(result.outputs[:, k] - exact).max() <= CLOSED_RTOL * exact.max(), k
    assert result.state_names == ("q(C1)", "q(C2)", "i(L1)")
    # the charge state of C1 is ∫ C dv, not C(v)·v
    q = result.states[-1, 0]
    assert abs(q - 1e-9 * (v[-1] + v[-1] ** 2 / 2)) <= 1e-9 * abs(q)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("C2 a 0 {1n*(1+v(a))}\n", "C2: a value that reads v(), i() or time is written C={...}"),
        ("C2 a 0 C={1n*(1+v(b))}\nR2 b 0 1k\n", "C2: C={...} may read only its own voltage"),
        ("C2 a 0 C={1n*(1+time)}\n", "C2: C={...} may read only its own voltage"),
        ("C2 a b C={1n*(1+v(a))}\nR2 b 0 1k\n", "C2: C={...} reads one end of a floating capacitor"),
        ("C2 a b C={1n*(1+v(a)*v(b))}\nR2 b 0 1k\n", "must depend on v(a)-v(b) only"),
        ("C2 a 0 C={1n*(1+v(a))} m=2\n", "C2: m= beside a nonlinear C= is not supported"),
        ("L2 a 0 L={1m*(1+i(V1))}\n", "L2: L={...} may read only i(Vx) of a voltage source Vx in series"),
        ("Vm a b 0\nL2 b 0 L={1m*(1+i(Vm))}\nL3 a 0 1m\nK1 L2 L3 0.5\n", "K1: a coupling of a nonlinear"),
    ],
)
def test_bad_inputs_one_line(body: str, message: str) -> None:
    assert_one_line_error("t\nV1 a 0 1\nR1 a 0 1k\n" + body + ".end\n", message)


def test_validate_writes_the_forms_back_for_ngspice() -> None:
    """validate: ngspice runs C=, Q=, L= as netlistdyn wrote them; the nonlinear transient agrees."""
    pytest.importorskip("PySpice")
    import shutil

    if shutil.which("ngspice") is None:
        pytest.skip("ngspice is not installed")
    import netlistdyn

    text = CIRCUIT.format(src="PULSE(0 2 0.5u 0.2u 0.2u 3u 10u)") + ".end\n"
    check = netlistdyn.validate(text, tstop="2u", tstep="20n", pz=False)
    assert check.passed
    assert max(c.max_rel_error for c in check.report.comparisons) <= TRAN_RTOL
