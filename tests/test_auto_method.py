"""``simulate --method auto`` picks the stepping by the problem, not only the size (issue 28).

The descriptor form's CF stepping takes one step per output interval on a real spectrum however
stiff; ``rational`` resolves the fast modes the input's corners excite (a 30x30 RC grid: 29 s of
CPU against CF's 2.2 s). ``auto`` takes the descriptor form when the circuit's fastest rate,
estimated from the diagonal of the pencil, times the output step exceeds STIFF_STEP_RATIO, and
stays with the explicit model where that cannot serve (LC modes, SIN sources, small models,
outputs the descriptor form does not give).
"""

from __future__ import annotations

import pytest

from netlistdyn.formulation.descriptor import assemble
from netlistdyn.frontend.parser import parse_text
from netlistdyn.workflows.large import STIFF_STEP_RATIO, simulate_descriptor_wanted, stiffness_ratio

#: Reactive elements above which ``exact`` gives way here (the CLI passes EXACT_LIMIT, 400).
LIMIT = 10


def _rc_line(sections: int, source: str = "PWL(0 0 1n 1 2n 0)", tstep: str = "1n") -> str:
    """An RC line, 1 Ω and 1 pF per section: node rates 2e12 1/s, far above 1/tstep."""
    lines = ["rc line", f"V1 n0 0 {source}"]
    for k in range(1, sections + 1):
        lines += [f"R{k} n{k - 1} n{k} 1", f"C{k} n{k} 0 1p"]
    return "\n".join([*lines, f".tran {tstep} 100n", ".end"]) + "\n"


def _lc_ladder(sections: int) -> str:
    lines = ["lc ladder", "V1 n0 0 PWL(0 0 1u 1)"]
    for k in range(1, sections + 1):
        lines += [f"R{k} n{k - 1} m{k} 1", f"L{k} m{k} n{k} 1m", f"C{k} n{k} 0 1u"]
    return "\n".join([*lines, ".tran 1u 1m", ".end"]) + "\n"


def test_rc_line_stiffness_is_the_node_rate_times_the_step() -> None:
    """Node k of the line: (1 + 1) S / 1 pF = 2e12 1/s; times the 1 ns step: 2000."""
    net = parse_text(_rc_line(20))
    assert stiffness_ratio(assemble(net), 1e-9) == pytest.approx(2000.0, rel=1e-12)


def test_auto_takes_the_descriptor_form_for_a_stiff_rc_line() -> None:
    assert simulate_descriptor_wanted(parse_text(_rc_line(20)), "auto", None, None, None, LIMIT)


@pytest.mark.parametrize(
    ("text", "method", "outputs", "why"),
    [
        (_rc_line(20), "rational", None, "a method was asked for"),
        (_rc_line(5), "auto", None, "small: exact wins"),
        (_rc_line(20, tstep="1p"), "auto", None, "rate·step 2: not stiff"),
        (_rc_line(20, source="SIN(0 1 1e8)"), "auto", None, "a SIN source: not piecewise linear"),
        (_rc_line(20), "auto", ["v(n3)", "i(C3)"], "i(C) is not a descriptor output"),
        (_lc_ladder(20), "auto", None, "LC modes: no diagonal rate"),
    ],
)
def test_auto_keeps_the_explicit_model(text: str, method: str, outputs: list[str] | None, why: str) -> None:
    assert STIFF_STEP_RATIO > 2
    assert not simulate_descriptor_wanted(parse_text(text), method, outputs, None, None, LIMIT), why
