"""The reduction to A, B, C, D at realistic and extreme values (issues on realistic values).

Each test compares with an independent computation: the transfer function
of the model's own velocity output divided by s (a displacement is the
integral of a velocity), the floating-point MNA of :mod:`tests.mna`, the
exact rational reference of :mod:`tests.exact_pencil`, or numbers ngspice
39 printed for the same netlist (quoted with the command).
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.cli import main
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_file, parse_text
from tests.conftest import NETLISTS
from tests.exact_pencil import exact_natural_frequencies
from tests.mna import build_mna

#: Transfer values computed two ways in double precision agree to this (relative): the models
#: are small and well conditioned at the frequencies used, so rounding stays near 1e-13.
TRANSFER_RTOL = 1e-9
#: The ngspice values below were printed with 12 significant digits (`set numdgt=12`).
NGSPICE_PRINTED = 1e-10

S_POINTS = (0.37 + 1.1j, 2.0 + 0.0j, -0.05 + 3.0j)


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(float(np.max(np.abs(b))), 1e-300))


@pytest.mark.parametrize(
    ("name", "node"),
    [("two_blocks.cir", "b1"), ("two_blocks.cir", "b2"), ("servo_shaft.cir", "load")],
)
def test_held_displacement_is_the_integral_of_the_velocity(name, node):
    """x(n) computed from spring forces equals v(n)/s (the model's own velocity, integrated)."""
    netlist = parse_file(NETLISTS / name)
    model = compile_netlist(netlist, [f"x({node})", f"v({node})"])
    for s in S_POINTS:
        g = model.transfer_function(s)
        assert _relative(g[0], g[1] / s) <= TRANSFER_RTOL


def test_springs_to_the_frame_need_no_integrator():
    """Two blocks with x(b1), x(b2): 4 states (the order of the exact pencil), asymptotically stable."""
    netlist = parse_file(NETLISTS / "two_blocks.cir")
    model = compile_netlist(netlist, ["x(b1)", "x(b2)"])
    assert model.nstates == len(exact_natural_frequencies(netlist)) == 4
    assert not model.info.integrators
    assert analyze_eigenvalues(model.A_sparse, pencil=model.pencil).verdict == "asymptotically stable"


def test_free_chain_needs_one_integrator():
    """Servo: the shaft turns freely, so x(shaft) is integrated once and x(load) follows by the spring."""
    netlist = parse_file(NETLISTS / "servo_shaft.cir")
    model = compile_netlist(netlist, ["x(shaft)", "x(load)", "v(shaft)", "v(load)", "i(L1)"])
    assert model.info.integrators == ("x(shaft)",)
    eig = analyze_eigenvalues(model.A_sparse, pencil=model.pencil)
    assert eig.verdict == "marginally stable"  # the pole at 0 of a free shaft, and nothing worse


COUPLED = """coupled inductors {title}
V1 in 0 AC 1
R1 in a 1
L1 a 0 {l1}
L2 b 0 {l2}
R2 b 0 1
{couplings}
.ac lin 1 1k 1k
.print ac v(b)
.end
"""

# v(b) at 1 kHz from `ngspice -b` (ngspice 39) on each netlist above, with a control block
# `set numdgt=12`, `ac lin 1 1k 1k`, `print v(b)` in place of the .ac/.print lines.
NGSPICE_V_B = {
    "both negative": complex(-2.23645836622e-02, -6.90739337203e-02),
    "mixed signs": complex(-2.79748204613e-03, 4.438797831923e-02),
    "two K on one pair": complex(1.209981665454e-01, -1.76041784433e-01),
}


@pytest.mark.parametrize(
    ("title", "l1", "l2", "couplings"),
    [
        ("both negative", "-1m", "-2m", "K1 L1 L2 0.5"),
        ("mixed signs", "1m", "-2m", "K1 L1 L2 0.5"),
        ("two K on one pair", "1m", "2m", "K1 L1 L2 0.5\nK2 L1 L2 0.3"),
    ],
)
def test_mutual_inductance_as_ngspice(title, l1, l2, couplings):
    """M = k·sqrt(|L1·L2|) whatever the signs, couplings on one pair add: as ngspice reads it."""
    netlist = parse_text(COUPLED.format(title=title, l1=l1, l2=l2, couplings=couplings))
    model = compile_netlist(netlist, ["v(b)"])
    s = 2j * np.pi * 1e3
    ours = model.transfer_function(s)[0, 0]
    assert abs(ours - NGSPICE_V_B[title]) <= NGSPICE_PRINTED * abs(NGSPICE_V_B[title])
    reference = build_mna(netlist).transfer(["v(b)"], s)[0, 0]
    assert abs(ours - reference) <= TRANSFER_RTOL * abs(reference)


def test_total_coupling_above_one_is_read_as_ngspice_with_a_warning():
    """Two K on one pair adding to 1.1: ngspice and Xyce simulate it (indefinite inductance matrix);
    so do we, naming the couplings in a warning and not calling the model passive."""
    text = COUPLED.format(title="too much", l1="1m", l2="2m", couplings="K1 L1 L2 0.6\nK2 L1 L2 0.5")
    netlist = parse_text(text)
    model = compile_netlist(netlist, ["v(b)"])
    assert any(
        "K1, K2: the inductance matrix of L1, L2 is not positive" in w.message for w in model.info.warnings
    )
    assert not model.info.passive
    s = 2j * np.pi * 1e3
    reference = build_mna(netlist).transfer(["v(b)"], s)[0, 0]
    assert abs(model.transfer_function(s)[0, 0] - reference) <= TRANSFER_RTOL * abs(reference)


def test_value_that_overflows_is_an_error(tmp_path):
    """R = 1e-308 makes 1/(R·C) overflow: an error naming R1, never a model holding inf."""
    path = tmp_path / "tiny.cir"
    path.write_text("tiny\nV1 in 0 1\nR1 in a 1e-308\nC1 a 0 1\n.end\n")
    result = CliRunner().invoke(main, ["analyze", str(path), "--eig", "none", "--format", "json"])
    assert result.exit_code != 0
    assert "tiny.cir:3: R1: value 1e-308" in result.output
