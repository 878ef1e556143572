"""Malformed input never escapes as anything but a NetlistError or UsageError.

Hypothesis writes netlist-like text from SPICE's own vocabulary (element
letters, mechanical keywords, dot-commands, SPICE numbers with suffixes,
waveform functions, parentheses, '=', '+' continuations, comments) and from
arbitrary characters, and output specifications likewise; parsing and
compiling must either succeed or raise one of the two error types the command
line turns into a one-line message. (Found: a line of only delimiters, '(',
crashed the parser.)
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from netlistdyn.base.errors import NetlistError, UsageError
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_text


def compile_or_refuse(text: str, outputs: list[str] | None = None) -> None:
    """Compile, or be refused with a NetlistError/UsageError; a model must hold finite numbers."""
    try:
        model = compile_netlist(parse_text(text), outputs)
    except (NetlistError, UsageError):
        return
    for matrix in (model.A, model.B, model.C, model.D, model.D1):
        assert np.all(np.isfinite(matrix))


WORDS = st.sampled_from(
    [
        "R1", "C1", "L1", "V1", "I1", "E1", "F1", "G1", "H1", "K1", "X1", "Q1",
        "MASS", "SPRING", "DAMPER", "FORCE", "VELOCITY", "GEAR", "MOTOR", "ROD", "INERTIA", "TORQUE",
        ".param", ".tran", ".subckt", ".ends", ".end", ".include", ".model", ".ic",
        "0", "a", "b", "in", "out", "gnd", "n1",
        "1", "0", "-1", "1k", "10uF", "1meg", "2.5m", "1e-3", "1e400", "nan", "inf", "1mil", "{R}", "{1/0}",
        "{R*", "R=1", "g=9.81", "inverted", "DC", "AC", "PULSE(0", "1", "0", "1m", "1m", "1m", "5m)",
        "SIN(0", "1", "50)", "PWL(0", "0", "1m", "1)", "EXP(0", "1)", "(", ")", "=", ",", ";", "*",
        "V1", "L2", "C2",
    ]
)  # fmt: skip
LINES = st.one_of(
    st.lists(WORDS, min_size=1, max_size=8).map(" ".join),
    st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=30),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(LINES, min_size=0, max_size=10))
def test_malformed_netlists_give_netlist_errors(lines: list[str]) -> None:
    compile_or_refuse("fuzz\n" + "\n".join(lines) + "\n")


VALID_BASE = "base\nV1 in 0 DC 1\nR1 in a 1k\nC1 a 0 1u\nL1 a b 1m\nR2 b 0 10\n"


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.lists(WORDS, min_size=1, max_size=7).map(" ".join), min_size=1, max_size=3))
def test_appending_lines_to_a_valid_netlist(lines: list[str]) -> None:
    compile_or_refuse(VALID_BASE + "\n".join(lines) + "\n")


PROBE_TEXT = st.one_of(
    st.text(alphabet="vixangle()ab,01RLC1 ._", max_size=14),
    st.text(max_size=10),
)


@settings(max_examples=300, deadline=None)
@given(PROBE_TEXT)
def test_malformed_output_specs_give_usage_errors(spec: str) -> None:
    compile_or_refuse(VALID_BASE, [spec])
