"""Fuzzing the whole pipeline: parse → compile → eigenvalues.

Hypothesis builds circuits from SPICE's element vocabulary on a handful of nodes, with values
drawn from realistic ranges (mΩ..GΩ, pF..mF, µH..H, gains, couplings), `.param` expressions,
subcircuits and mechanical keywords, then damages some lines (a token dropped, duplicated or
replaced). Every netlist must either be refused with a :class:`NetlistError`/:class:`UsageError`
or give a model with finite matrices and finite eigenvalues. Anything else is a bug.

The CI budget is small (``NETLISTDYN_FUZZ_EXAMPLES``, default 200); the long run reported in the
README is::

    NETLISTDYN_FUZZ_EXAMPLES=100000 taskset -c 0 python -m pytest -q -p no:cacheprovider \\
        tests/test_fuzz_pipeline.py
"""

from __future__ import annotations

import os

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.base.errors import NetlistError, UsageError
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_text

EXAMPLES = int(os.environ.get("NETLISTDYN_FUZZ_EXAMPLES", "200"))
NODES = ["0", "a", "b", "c", "d", "e"]
SUFFIX = {"": 1.0, "m": 1e-3, "u": 1e-6, "n": 1e-9, "p": 1e-12, "k": 1e3, "meg": 1e6, "g": 1e9}


def spice_number(low: float, high: float) -> st.SearchStrategy[str]:
    """A SPICE number between low and high (log-uniform), written with a suffix when it fits."""

    def write(exponent: float, suffix: str) -> str:
        value = 10.0**exponent
        scale = SUFFIX[suffix]
        return f"{value / scale:.4g}{suffix}"

    return st.builds(write, st.floats(np.log10(low), np.log10(high)), st.sampled_from(list(SUFFIX)))


VALUES = {
    "R": spice_number(1e-3, 1e9),
    "C": spice_number(1e-12, 1e-3),
    "L": spice_number(1e-6, 1.0),
    "V": spice_number(1e-3, 1e3),
    "I": spice_number(1e-6, 10.0),
    "gain": spice_number(1e-3, 1e3),
    "MASS": spice_number(1e-3, 1e3),
    "SPRING": spice_number(1.0, 1e6),
    "DAMPER": spice_number(1e-2, 1e4),
}
node = st.sampled_from(NODES)


@st.composite
def element(draw: st.DrawFn, index: int) -> str:
    kind = draw(st.sampled_from("RRRRCCCLLLVVIEGFHKXP"))
    a, b = draw(node), draw(node)
    if kind in "RCLVI":
        value = draw(VALUES[kind])
        if kind in "VI" and draw(st.booleans()):
            value = draw(
                st.sampled_from(
                    [
                        f"PULSE(0 {value} 0 1u 1u 1m 2m)",
                        f"SIN(0 {value} 1k)",
                        f"PWL(0 0 1m {value})",
                        f"EXP(0 {value} 0 1m)",
                        f"DC {value}",
                    ]
                )
            )
        elif draw(st.integers(0, 5)) == 0:
            value = "{p1*2}"
        return f"{kind}{index} {a} {b} {value}"
    if kind in "EG":
        return f"{kind}{index} {a} {b} {draw(node)} {draw(node)} {draw(VALUES['gain'])}"
    if kind in "FH":
        sense = draw(st.sampled_from(["Vs", "Vs", f"V{draw(st.integers(0, 6))}"]))
        return f"{kind}{index} {a} {b} {sense} {draw(VALUES['gain'])}"
    if kind == "K":
        k = draw(st.floats(-0.999, 0.999).map(lambda x: f"{x:.3g}"))
        return f"K{index} L{draw(st.integers(0, 6))} L{draw(st.integers(0, 6))} {k}"
    if kind == "X":
        return f"X{index} {a} {b} half"
    word = draw(st.sampled_from(["MASS", "SPRING", "DAMPER", "FORCE", "ROD"]))
    if word == "MASS":
        return f"MASS m{index} {a} {draw(VALUES['MASS'])}"
    if word == "FORCE":
        return f"FORCE f{index} {a} {b} {draw(VALUES['I'])}"
    if word == "ROD":
        return f"ROD r{index} {a} {b} {draw(spice_number(1e-2, 10.0))}"
    return f"{word} k{index} {a} {b} {draw(VALUES[word])}"


@st.composite
def damaged(draw: st.DrawFn, line: str) -> str:
    tokens = line.split()
    how = draw(st.integers(0, 24))
    if how == 0 and len(tokens) > 1:
        del tokens[draw(st.integers(1, len(tokens) - 1))]
    elif how == 1:
        tokens.insert(draw(st.integers(1, len(tokens))), draw(st.sampled_from(tokens)))
    elif how == 2:
        tokens[draw(st.integers(0, len(tokens) - 1))] = draw(
            st.sampled_from(["0", "1e400", "-1", "{1/0}", "nan", "(", "=", "{p9}", "1mil", "x"])
        )
    return " ".join(tokens)


@st.composite
def netlists(draw: st.DrawFn) -> str:
    count = draw(st.integers(1, 9))
    lines = [draw(element(k)) for k in range(count)]
    lines = [draw(damaged(line)) for line in lines]
    header = [
        "fuzzed circuit",
        f".param p1={draw(VALUES['R'])}",
        ".subckt half p n",
        f"R1 p mid {draw(VALUES['R'])}",
        f"C1 mid n {draw(VALUES['C'])}",
        ".ends",
        f"Vs a 0 {draw(VALUES['V'])}",
    ]
    return "\n".join(header + lines) + "\n"


def check_netlist(text: str) -> int | None:
    """Compile ``text`` and check its model; the state count, or None when it is refused cleanly.

    Raises
    ------
    AssertionError
        When the model holds a non-finite entry or its eigenvalues are not all finite.
    """
    try:
        model = compile_netlist(parse_text(text))
    except (NetlistError, UsageError):
        return None
    for matrix in (model.A_sparse, model.B_sparse, model.C_sparse, model.D_sparse, model.D1_sparse):
        assert np.all(np.isfinite(matrix.data))
    analysis = analyze_eigenvalues(model.A_sparse)
    values = np.array([mode.value for mode in analysis.modes], dtype=complex)
    assert values.size == model.nstates
    assert np.all(np.isfinite(values))
    return model.nstates


@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
@given(netlists())
def test_parse_compile_eigenvalues(text: str) -> None:
    check_netlist(text)
