"""Where the transient starts: ngspice's rules for ``.tran ... UIC``, ``.ic`` and ``IC=``.

Each circuit is run by ``ngspice -b`` on its own text (``.options reltol=1e-9``, a maximum step
far below its time constants) and by netlistdyn from the start it chooses, propagated exactly
to ngspice's time points; they must agree to :data:`TOLERANCE` of each output's peak.
``simulate`` must give the same numbers, and ``validate`` must pass on each (it hands ngspice
the same start). The circuits cover: the operating point with a
nonzero source (no UIC), ``UIC`` with ``IC=`` on C and L, ``.ic`` held during the operating point
and released, and ``.ic`` under ``UIC`` (capacitor voltages from the node values).
"""

from __future__ import annotations

import numpy as np
import pytest

import netlistdyn
from netlistdyn.base.errors import NetlistError
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_text
from netlistdyn.simulation.foh import input_signals, propagate_foh
from netlistdyn.simulation.initial import transient_start
from tests.ngspice_probe import needs_ngspice, ngspice_tran

RLC = "V1 in 0 DC 1\nR1 in a 100\nC1 a 0 1u\nL1 a b 10m{lic}\nR2 b 0 50\nC2 b 0 2.2u\n"
CIRCUITS = {
    # Operating point: 2 V through the divider, then the PULSE falls to 0 at 1 ms.
    "operating_point": "V1 in 0 DC 2 PULSE(2 0 1m 10u 10u 1 2)\nR1 in a 1k\nC1 a 0 470n\nR2 a 0 3.3k\n"
    ".tran 10u 4m 0 0.25u\n",
    "uic_element_ic": "V1 in 0 DC 2\nR1 in a 1k\nC1 a 0 470n IC=-1\nR2 a 0 3.3k\n"
    "L1 a c 22m IC=-4m\nR3 c 0 68\n.tran 10u 4m 0 0.25u uic\n",
    "ic_held_then_released": RLC.format(lic="") + ".ic v(a)=3\n.tran 10u 4m 0 0.25u\n",
    "ic_under_uic": RLC.format(lic=" IC=5m") + ".ic v(a)=3 v(b)=-1\n.tran 10u 4m 0 0.25u uic\n",
    # Every source 0 at t = 0: the operating point is zero, and the IC= values do not count.
    "ic_ignored_without_uic": "V1 in 0 PULSE(0 1 0.2m 10u 10u 1 2)\nR1 in a 1k\nC1 a 0 470n IC=1\n"
    "L1 a c 22m IC=1m\nR3 c 0 680\n.tran 10u 4m 0 0.25u\n",
}
#: ngspice's trapezoidal rule at its 0.25 µs maximum step against our exact propagation: the
#: fastest mode here is |λ| ≈ 1.2e4 /s, so each step's error is about (|λ|h)³/12 ≈ 2e-9 of the
#: peak and a few hundred steps of the decay accumulate < 1e-6 (measured: 4.6e-7 at h = 0.25 µs,
#: 7e-6 at 1 µs, the h² ratio).
TOLERANCE = 2e-6
OUTPUTS = {
    "operating_point": ["v(a)"],
    "uic_element_ic": ["v(a)", "v(c)"],
    "ic_ignored_without_uic": ["v(a)", "v(c)"],
}


@needs_ngspice
@pytest.mark.parametrize("name", sorted(CIRCUITS))
def test_start_as_ngspice(name: str) -> None:
    text = f"{name}\n{CIRCUITS[name]}"
    outputs = OUTPUTS.get(name, ["v(a)", "v(b)"])
    deck = text.replace(".tran", ".options reltol=1e-9 abstol=1e-15 vntol=1e-12\n.tran")
    theirs = ngspice_tran(deck, outputs)
    times = theirs[:, 0]
    netlist = parse_text(text)
    model = compile_netlist(netlist, outputs)
    signals = input_signals(netlist, netlist.tran.tstep, netlist.tran.tstop)
    start = transient_start(netlist, model, signals(np.array([0.0]))[0])
    ours = propagate_foh(model, signals, times, start.x0).outputs  # exact, at ngspice's times
    for j, name_out in enumerate(outputs):
        peak = np.max(np.abs(theirs[:, j + 1]))
        assert peak > 0.1
        assert np.max(np.abs(ours[:, j] - theirs[:, j + 1])) < TOLERANCE * peak, name_out
    # simulate's own path (uniform grid, its start) gives the same numbers at its points.
    result = netlistdyn.simulate(text, outputs=outputs, tstep=1e-4)
    exact = propagate_foh(model, signals, result.time, start.x0).outputs
    assert np.max(np.abs(result.values - exact)) < 1e-9 * np.max(np.abs(exact))
    check = netlistdyn.validate(text, outputs=outputs, pz=False)
    assert check.report.passed, check.report.notes


def _start(text: str) -> np.ndarray:
    netlist = parse_text(text)
    model = compile_netlist(netlist)
    u0 = input_signals(netlist, 1e-6, 1e-3)(np.array([0.0]))[0]
    return transient_start(netlist, model, u0).x0


def test_uic_charge_and_current_in_state_units() -> None:
    x0 = _start("t\nV1 in 0 1\nR1 in a 1k\nC1 a 0 2u IC=3\nL1 a 0 5m IC=-2m\n.tran 1u 1m uic\n")
    assert x0 == pytest.approx([6e-6, -2e-3], rel=1e-15)  # q(C1) = C·v, i(L1)


def test_operating_point_closed_form() -> None:
    # Divider 1k / 3k from 4 V: v(a) = 3 V; q(C1) = 1u·3; i(L1) in series with R3 carries 0 (C blocks).
    x0 = _start("t\nV1 in 0 4\nR1 in a 1k\nR2 a 0 3k\nC1 a 0 1u\nL1 in b 1m\nR3 b 0 2k\n.tran 1u 1m\n")
    assert x0 == pytest.approx([3e-6, 2e-3], rel=1e-12)


def test_without_tran_the_start_is_rest() -> None:
    assert not np.any(_start("t\nV1 in 0 4\nR1 in a 1k\nC1 a 0 1u\n"))


def test_element_ic_without_uic_is_ignored_with_a_warning() -> None:
    netlist = parse_text("t\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u IC=5\n.tran 1u 1m\n")
    model = compile_netlist(netlist)
    start = transient_start(netlist, model, np.array([1.0]))
    assert start.x0 == pytest.approx([1e-6], rel=1e-12)
    assert any("UIC" in w.message for w in start.warnings)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        # A node only capacitors reach: no unique operating point (ngspice: singular matrix).
        ("V1 a 0 1\nR1 a b 1k\nC2 b c 1u\nC3 c 0 1u\n.tran 1u 1m\n", "no unique DC operating point"),
        # A capacitor that is not a state (a loop of capacitors) cannot take its own IC=.
        (
            "V1 a 0 1\nR1 a b 1k\nC1 b 0 1u\nC2 b c 1u\nC3 c 0 1u IC=1\nC4 b 0 1u IC=2\n.tran 1u 1m uic\n",
            "not a state",
        ),
        (".ic v(nowhere)=1\nV1 a 0 1\nR1 a b 1k\nC1 b 0 1u\n.tran 1u 1m\n", "no node 'nowhere'"),
    ],
)
def test_starts_that_cannot_be_imposed_are_refused(text: str, fragment: str) -> None:
    with pytest.raises(NetlistError, match=fragment) as info:
        _start("t\n" + text)
    assert "\n" not in str(info.value)


def test_displacement_output_starts_at_zero_from_the_operating_point() -> None:
    """A mass on a damper pushed by 8 N: at the operating point it moves at F/d = 2 m/s, and its
    displacement x(a), an integrator of that velocity, starts at 0 and grows as 2·t (exact)."""
    text = "slide\nMASS m1 a 2\nDAMPER d1 a 0 4\nFORCE f1 a 0 8\n.tran 10m 1\n"
    result = netlistdyn.simulate(text, outputs=["x(a)", "v(a)"])
    assert result.start == "DC operating point"
    np.testing.assert_allclose(result["v(a)"], 2.0, rtol=1e-12)
    np.testing.assert_allclose(result["x(a)"], 2.0 * result.time, rtol=1e-10, atol=1e-12)


@needs_ngspice
@pytest.mark.parametrize("name", sorted(CIRCUITS))
def test_descriptor_start_as_ngspice(name: str) -> None:
    """The sparse descriptor form applies the same rules (``IC=``, ``.ic`` held or under UIC).

    Run at rtol 1e-12 on a 10 µs grid and compared with ngspice's run interpolated linearly onto
    it: ngspice's points are at most 0.25 µs apart, so the interpolation adds h²/8·|v''| ≈ 4e-8 of
    the peak (slowest time constant 0.47 ms) to the TOLERANCE above. The t = 0 sample is left out:
    under UIC it is taken 1e-9 of a step after the start (see transient._consistent).
    """
    from netlistdyn.workflows.large import simulate_large

    text = f"{name}\n{CIRCUITS[name]}"
    outputs = OUTPUTS.get(name, ["v(a)", "v(b)"])
    deck = text.replace(".tran", ".options reltol=1e-9 abstol=1e-15 vntol=1e-12\n.tran")
    theirs = ngspice_tran(deck, outputs)
    warnings: list = []
    ours = simulate_large(parse_text(text), outputs, None, None, (), rtol=1e-12, warn=warnings.append)
    assert ours.ok, ours.message
    for j, name_out in enumerate(outputs):
        ref = np.interp(ours.time, theirs[:, 0], theirs[:, j + 1])
        peak = np.max(np.abs(ref))
        assert peak > 0.1
        assert np.max(np.abs(ours.values[1:, j] - ref[1:])) < TOLERANCE * peak, name_out
    assert bool(warnings) is (name == "ic_ignored_without_uic")  # IC= without UIC: said, not applied


@needs_ngspice
def test_descriptor_uic_capacitor_loop_conserves_node_charge_as_ngspice() -> None:
    """C1 (IC=1), C2 (0 V: no IC=, no .ic) and C3 (IC=0.4) form a loop whose values disagree. The
    explicit model refuses C3 (not a state); the descriptor form sets each capacitor's charge and
    lets the first instant share it out, node charge conserved — ngspice's start too (v(a) = 0.8,
    v(b) = 0.6). Tolerance as in test_descriptor_start_as_ngspice."""
    from netlistdyn.workflows.large import simulate_large

    text = (
        "t\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u IC=1\nC2 a b 1u\nC3 b 0 1u IC=0.4\nR3 b 0 1k\n.tran 10u 4m uic\n"
    )
    deck = text.replace(
        ".tran 10u 4m uic", ".options reltol=1e-9 abstol=1e-15 vntol=1e-12\n.tran 10u 4m 0 0.25u uic"
    )
    theirs = ngspice_tran(deck, ["v(a)", "v(b)"])
    ours = simulate_large(parse_text(text), ["v(a)", "v(b)"], None, None, (), rtol=1e-12)
    assert ours.ok, ours.message
    # Node charges 1 uC and 0.4 uC kept: 2 v(a) - v(b) = 1 and 2 v(b) - v(a) = 0.4 (closed form).
    assert ours.values[0] == pytest.approx([0.8, 0.6], rel=1e-8)
    for j in range(2):
        ref = np.interp(ours.time, theirs[:, 0], theirs[:, j + 1])
        assert np.max(np.abs(ours.values[1:, j] - ref[1:])) < TOLERANCE * np.max(np.abs(ref))


@pytest.mark.parametrize("scale", [1.0, 1e-3, 1e3])
def test_operating_point_at_realistic_values_is_found(scale: float) -> None:
    """An RLC ladder at realistic values (50 Ω, 10 µH, 1 nF, 1 µH, 100 pF, 1 kΩ, 1 MΩ; and the same
    with every L and C scaled by 1e-3 and 1e3) has a unique operating point: every node at
    V·(R2 ∥ R3)/(R1 + R2 ∥ R3). Its A has entries decades apart (charges beside currents), and the
    unscaled condition number once called it singular. Tolerance 1e-12 relative: one dense solve of
    an equilibrated 4 × 4 system."""
    text = (
        "rlc at realistic values\nV1 in 0 DC 1\nR1 in a 50\n"
        f"L1 a b {10e-6 * scale}\nC1 b 0 {1e-9 * scale}\nR2 b 0 1k\n"
        f"L2 b c {1e-6 * scale}\nC2 c 0 {100e-12 * scale}\nR3 c 0 1meg\n.tran 1n 2u\n.end\n"
    )
    netlist = parse_text(text)
    model = compile_netlist(netlist, ["v(b)", "v(c)", "i(L1)"])
    x0 = transient_start(netlist, model, np.array([1.0])).x0
    parallel = 1e3 * 1e6 / (1e3 + 1e6)
    v = parallel / (50 + parallel)
    np.testing.assert_allclose(model.C @ x0 + model.D @ [1.0], [v, v, v / parallel], rtol=1e-12)
