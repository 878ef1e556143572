"""Issue 15: the notes' own coordinates, initial conditions in physical variables, validity warnings.

The reference matrices are the notes' formulas (their linearisations, written
out from the Lagrangians and Newton's laws they print), evaluated at the
netlists' values. ENTRY_RTOL 1e-12: ours is T A T⁻¹ with cond(T) ≤ 6e4, so
rounding reaches ~1e-16 · cond(T) of each matrix's largest entry; an error in
a mass, a length or a sign shows up at O(1). The printed matrices (rounded
to 4-5 digits) are checked at their printed precision.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from netlistdyn.analysis.coordinates import prepare
from netlistdyn.cli import main
from netlistdyn.frontend.parser import parse_file, parse_text
from netlistdyn.io.exports import load_model

from .conftest import NETLISTS

ENTRY_RTOL = 1e-12
#: scipy's lsim and our exact method are both exact for piecewise-linear inputs on
#: the grid; the DIPC's unstable mode (9.17/s) amplifies rounding by e^{9.17·1.5} ≈ 1e6.
LSIM_RTOL = 1e-8


def assert_entries(actual: np.ndarray, expected: np.ndarray) -> None:
    scale = np.abs(expected).max()
    np.testing.assert_allclose(actual, expected, rtol=ENTRY_RTOL, atol=ENTRY_RTOL * scale)


def in_coordinates(name: str, coords: str, params: dict[str, float] | None = None):
    return prepare(parse_file(NETLISTS / name, params or {}), None, coords).change


def second_order(M, K, D, E):
    """x = (q, q'), M q'' + D q' + K q = E u  ->  A, B."""
    n = M.shape[0]
    Minv = np.linalg.inv(M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ D]])
    B = np.vstack([np.zeros((n, E.shape[1])), Minv @ E])
    return A, B


@pytest.mark.parametrize(
    "params",
    [{}, {"d": 100}, {"k1": 3e3, "k2": 120, "m1": 0.25, "m2": 40, "d": 2.5}],
)
def test_two_blocks_in_the_notes_coordinates(params) -> None:
    """Seed 000: x1, x2, x1', x2' with forces F1 on m1 and F2 on m2."""
    p = {"k1": 1, "k2": 1, "m1": 1, "m2": 1, "d": 0.001, **params}
    k1, k2, m1, m2, d = p["k1"], p["k2"], p["m1"], p["m2"], p["d"]
    A, B = second_order(
        np.diag([m1, m2]), np.array([[k1 + k2, -k2], [-k2, k2]]), np.array([[2 * d, -d], [-d, d]]), np.eye(2)
    )
    change = in_coordinates("two_blocks.cir", "x(b1),x(b2),v(b1),v(b2)", params)
    assert change.model.states == ("x(b1)", "x(b2)", "v(b1)", "v(b2)")
    assert_entries(change.model.A, A)
    assert_entries(change.model.B, B)
    # Without --output the outputs are the coordinates themselves.
    assert_entries(change.model.C, np.eye(4))


@pytest.mark.parametrize("params", [{}, {"l": 100}, {"inv": 1}, {"m3": 0.2, "d": 0.05, "l": 0.4}])
def test_blocks_pendulum_in_the_notes_coordinates(params) -> None:
    """Seed 000: q = (x1, x2, θ), the bob at x2 + l θ; M q'' + D q' + K q = [F1, F2, 0]."""
    p = {"k1": 1, "k2": 1, "m1": 1, "m2": 1, "m3": 1, "d": 1, "l": 1, "g": 10, "inv": 0, **params}
    m1, m2, m3, rod, g, d = p["m1"], p["m2"], p["m3"], p["l"], p["g"], p["d"]
    sign = -1 if p["inv"] else 1
    M = np.array([[m1, 0, 0], [0, m2 + m3, m3 * rod], [0, m3 * rod, m3 * rod * rod]])
    K = np.array([[p["k1"] + p["k2"], -p["k2"], 0], [-p["k2"], p["k2"], 0], [0, 0, sign * m3 * g * rod]])
    D = np.array([[2 * d, -d, 0], [-d, d, 0], [0, 0, 0]])
    A, B = second_order(M, K, D, np.array([[1, 0], [0, 1], [0, 0]]))
    change = in_coordinates("blocks_pendulum.cir", "x(b1),x(b2),angle(rod),v(b1),v(b2),omega(rod)", params)
    assert_entries(change.model.A, A)
    assert_entries(change.model.B, B)
    if not params:  # the notes' printed case 1 (integers)
        printed = [[-2, 1, 0, -2, 1, 0], [1, -1, 10, 1, -1, 0], [-1, 1, -20, -1, 1, 0]]
        assert_entries(change.model.A[3:], np.array(printed, dtype=float))


DIPC = "x(cart),angle(r1),angle(r2),v(cart),omega(r1),omega(r2)"


def dipc_matrices(M=1.5, m1=0.5, m2=0.75, l1=0.5, l2=0.75, g=9.81):
    """Seed 002's Lagrangian linearised at the upright position (θ = 0)."""
    mass = np.array(
        [
            [M + m1 + m2, (m1 + m2) * l1, m2 * l2],
            [(m1 + m2) * l1, (m1 + m2) * l1**2, m2 * l1 * l2],
            [m2 * l2, m2 * l1 * l2, m2 * l2**2],
        ]
    )
    # The potential's Hessian: the upright rods push away from θ = 0 (hence −).
    K = -np.diag([0, (m1 * l1 + m2 * l1) * g, m2 * l2 * g])
    return second_order(mass, K, np.zeros((3, 3)), np.array([[1.0], [0], [0]]))


def test_dipc_in_the_notes_coordinates() -> None:
    A, B = dipc_matrices()
    change = in_coordinates("dipc.cir", DIPC)
    assert_entries(change.model.A, A)
    assert_entries(change.model.B, B)
    # The notes print A's lower block and B to 4-5 digits; their "-8.1759" is a typo for
    # -(m1 + m2) g / M = -8.175 (they print -8.18 in the observability matrix).
    printed_A = [[0, -8.175, 0], [0, 65.4, -29.43], [0, -32.7, 32.7]]
    np.testing.assert_allclose(change.model.A[3:, :3], printed_A, atol=5e-5)
    np.testing.assert_allclose(change.model.B[3:, 0], [0.6667, -1.3333, 0], atol=5e-5)


TWO_PENDULA = """Two pendula on a cart with distinct masses (names free of the M/m case clash)
.param Mc={M} mb={m} l1={l1} l2={l2}
MASS cart cart {{Mc}}
ROD r1 cart b1 {{l1}} g=9.81 inverted
MASS m1 b1 {{mb}}
ROD r2 cart b2 {{l2}} g=9.81 inverted
MASS m2 b2 {{mb}}
FORCE F cart 0 DC 0
"""


@pytest.mark.parametrize(("M", "m", "l1", "l2"), [(1.0, 1.0, 1.0, 2.0), (2.5, 0.4, 0.3, 1.7)])
def test_two_pendula_cart_in_the_notes_coordinates(M, m, l1, l2) -> None:
    """Seed 003 (first approach; equation (10) prints mg/(M l2) in the θ1 row for mg/(M l1))."""
    g = 9.81
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    A[3, 1:3] = [-m * g / M, -m * g / M]
    A[4, 1:3] = [(M + m) * g / (l1 * M), m * g / (l1 * M)]
    A[5, 1:3] = [m * g / (l2 * M), (M + m) * g / (l2 * M)]
    B = np.array([[0], [0], [0], [1 / M], [-1 / (M * l1)], [-1 / (M * l2)]])
    if (M, m, l1, l2) == (1.0, 1.0, 1.0, 2.0):
        change = in_coordinates("two_pendula_cart.cir", DIPC)
    else:
        net = parse_text(TWO_PENDULA.format(M=M, m=m, l1=l1, l2=l2))
        change = prepare(net, None, DIPC).change
    assert_entries(change.model.A, A)
    assert_entries(change.model.B, B)


@pytest.mark.parametrize("params", [{}, {"inv": 1}, {"m1": 2.0, "m2": 0.3, "l1": 0.7, "l2": 1.6}])
def test_double_pendulum_in_angles(params) -> None:
    """The correct linearisation (the notes' own Jacobian keeps only the θ1 column, see shared/README)."""
    p = {"m1": 1.0, "m2": 1.0, "l1": 1.0, "l2": 1.0, "g": 10.0, "inv": 0, **params}
    m1, m2, l1, l2, g = p["m1"], p["m2"], p["l1"], p["l2"], p["g"]
    sign = -1 if p["inv"] else 1
    M = np.array([[(m1 + m2) * l1**2, m2 * l1 * l2], [m2 * l1 * l2, m2 * l2**2]])
    K = sign * np.diag([(m1 + m2) * g * l1, m2 * g * l2])
    A, _ = second_order(M, K, np.zeros((2, 2)), np.zeros((2, 1)))
    change = in_coordinates("double_pendulum.cir", "angle(r1),angle(r2),omega(r1),omega(r2)", params)
    assert_entries(change.model.A, A)


@pytest.mark.parametrize("K", [500.0, 50.0])
def test_servo_in_the_notes_coordinates(K) -> None:
    """Seed 003: (Δ, θ2, Ω, ω2, i) with Δ = θ1 − θ2 the shaft's twist, Ω = Δ'."""
    Km, R, L, Jm, J, N = 0.05, 1.2, 0.05, 8e-4, 0.02, 12.0
    A = np.array(
        [
            [0, 0, 1, 0, 0],
            [0, 0, 0, 1, 0],
            [-K * (1 / J + 1 / (N**2 * Jm)), 0, 0, 0, Km / (Jm * N)],
            [K / J, 0, 0, 0, 0],
            [0, 0, -Km * N / L, -Km * N / L, -R / L],
        ]
    )
    B = np.array([[0], [0], [0], [0], [1 / L]])
    change = in_coordinates("servo_shaft.cir", "x(shaft,load),x(load),v(shaft,load),v(load),i(L1)", {"K": K})
    assert_entries(change.model.A, A)
    assert_entries(change.model.B, B)
    assert 1 < change.condition < 1e6
    # Same input-output behaviour as the compiled model with the coordinates as outputs.
    from netlistdyn.analysis.coordinates import select_outputs

    original = select_outputs(change.original, change.model.outputs)
    for s in (0.5j, 3.0 + 170j, 20.0):
        np.testing.assert_allclose(
            change.model.transfer_function(s), original.transfer_function(s), rtol=1e-9
        )


@pytest.mark.parametrize(
    ("coords", "message"),
    [
        ("x(b1),x(b2),v(b1)", "missing 1 direction(s): one involving p(m2) (for instance v(b2))"),
        ("x(b1),x(b2),v(b1),v(b2),v(b1,b2)", "v(b1,b2) is a combination of v(b1), v(b2)"),
        ("x(b1),x(b2),v(b1),x(b1,b2)", "x(b1,b2) is a combination of x(b1), x(b2)"),
        ("x(b1),x(b1),v(b1),v(b2)", "x(b1) listed twice"),
        ("x(b1),x(b2),v(b1),v(nowhere)", "no node 'nowhere'"),
        ("x(b1),x(b2),v(b1),omega(k1)", "is not a ROD"),
    ],
)
def test_coordinates_refused(coords, message) -> None:
    result = CliRunner().invoke(main, ["analyze", str(NETLISTS / "two_blocks.cir"), "--coordinates", coords])
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert "Traceback" not in result.output


def test_coordinate_that_depends_on_an_input_is_refused() -> None:
    net = parse_text("v\nMASS m a 1\nSPRING k a b 4\nVELOCITY vs b 0 DC 1\n")
    with pytest.raises(Exception, match="depends on the input vs directly"):
        prepare(net, None, "x(a),v(b)")


def test_analyze_json_and_save_in_coordinates(tmp_path: Path) -> None:
    target = tmp_path / "dipc.npz"
    result = CliRunner().invoke(
        main,
        [
            "analyze",
            str(NETLISTS / "dipc.cir"),
            "--coordinates",
            DIPC,
            "--format",
            "json",
            "--save",
            str(target),
        ],
    )
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)
    assert doc["states"] == DIPC.split(",")
    assert doc["coordinates"]["condition"] == pytest.approx(np.linalg.cond(doc["coordinates"]["T"]), rel=1e-9)
    A, B = dipc_matrices()
    assert_entries(np.array(doc["A"]), A)
    saved = load_model(target)
    assert saved.states == tuple(DIPC.split(","))
    assert_entries(saved.A, A)
    assert_entries(saved.B, B)
    # Eigenvalues are those of the notes' characteristic polynomial s^6 - 98.1 s^4 + 1176.22 s^2.
    values = sorted(complex(re, im).real for re, im in doc["eigenvalues"])
    assert values[-1] == pytest.approx(9.1715235, rel=1e-6)


def test_api_compile_with_coordinates() -> None:
    import netlistdyn

    model = netlistdyn.compile(NETLISTS / "two_blocks.cir", coordinates=["x(b1)", "x(b2)", "v(b1)", "v(b2)"])
    assert model.states == ("x(b1)", "x(b2)", "v(b1)", "v(b2)")
    assert model.A[2, 0] == pytest.approx(-2.0, rel=ENTRY_RTOL)


# --- initial conditions in physical variables ------------------------------------------


def simulate_json(name: str, *args: str) -> dict:
    result = CliRunner().invoke(main, ["simulate", str(NETLISTS / name), "--format", "json", *args])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_dipc_from_the_notes_angles_matches_lsim() -> None:
    """The notes' run starts at θ1 = −0.01, θ2 = −0.02 rad; scipy's lsim on the notes' model."""
    from scipy.signal import lsim

    from netlistdyn.simulation.foh import input_signals

    doc = simulate_json(
        "dipc.cir",
        "--ic",
        "angle(r1)=-0.01",
        "--ic",
        "angle(r2)=-0.02",
        "--ic",
        "x(cart)=0",
        "--coordinates",
        DIPC,
    )
    t = np.array(doc["time"])
    ours = np.column_stack([doc["values"][name] for name in DIPC.split(",")])
    A, B = dipc_matrices()
    u = input_signals(parse_file(NETLISTS / "dipc.cir"), t[1] - t[0], t[-1])(t)[:, 0]
    _, y, _ = lsim((A, B, np.eye(6), np.zeros((6, 1))), u, t, X0=[0, -0.01, -0.02, 0, 0, 0], interp=True)
    err = np.abs(ours - y).max(axis=0) / np.abs(y).max(axis=0)
    assert err.max() < LSIM_RTOL, err
    assert ours[0, 1] == pytest.approx(-0.01, rel=1e-12) and ours[0, 2] == pytest.approx(-0.02, rel=1e-12)


def test_ic_mixes_variables_and_state_names() -> None:
    net = parse_file(NETLISTS / "two_blocks.cir")
    prepared = prepare(net, None, None, ["v(b1)=0.5", "f(k2)=-0.25", "x(b1)=0.125"])
    full = prepared.full
    y = full.C @ prepared.x0
    out = dict(zip(full.outputs, y, strict=True))
    assert out["v(b1)"] == pytest.approx(0.5, rel=1e-12)
    assert out["x(b1)"] == pytest.approx(0.125, rel=1e-12)
    assert prepared.x0[full.states.index("f(k2)")] == pytest.approx(-0.25, rel=1e-12)
    # f(k1) = k1 x(b1): the spring that holds b1 measures the same position.
    assert prepared.x0[full.states.index("f(k1)")] == pytest.approx(0.125, rel=1e-12)


@pytest.mark.parametrize(
    ("ics", "message"),
    [
        (["x(b2)=1"], "under-determined"),
        (["v(b1)=1", "v(b1)=2"], "over-determined"),
        (["v(b1)=1", "v(b2)=1", "v(b1,b2)=0"], "over-determined"),
        (["angle(b1)=1"], "no element 'b1'"),
        (["v(b1)"], "expected NAME=VALUE"),
    ],
)
def test_ic_refused(ics, message) -> None:
    args = [a for ic in ics for a in ("--ic", ic)]
    result = CliRunner().invoke(main, ["simulate", str(NETLISTS / "two_blocks.cir"), *args])
    assert result.exit_code == 2, result.output
    assert message in result.output


# --- validity warnings -------------------------------------------------------------------


def test_dipc_at_60_s_warns() -> None:
    doc = simulate_json("dipc.cir", "--ic", "angle(r1)=-0.01", "--ic", "angle(r2)=-0.02", "--tstop", "60")
    text = " ".join(doc["warnings"])
    assert "angle(r1) leaves the small-angle range" in text
    assert "the model is unstable" in text


def test_small_swing_does_not_warn() -> None:
    # The hanging pendulum pushed by 1 N swings well inside 0.14 rad.
    doc = simulate_json("blocks_pendulum.cir", "--output", "angle(rod)")
    assert max(abs(v) for v in doc["values"]["angle(rod)"]) < 0.14
    assert doc["warnings"] == []


def test_angle_bound_is_one_percent() -> None:
    from netlistdyn.analysis.validity import SMALL_ANGLE_LIMIT

    assert 1 - np.cos(SMALL_ANGLE_LIMIT) == pytest.approx(0.01, rel=1e-12)


def _ladder(sections: int) -> str:
    lines = ["ladder", "V1 n0 0 DC 1"]
    for k in range(sections):
        lines += [f"R{k} n{k} m{k} 1", f"L{k} m{k} n{k + 1} 1m", f"C{k} n{k + 1} 0 1u"]
    return "\n".join(lines) + "\n"


def test_large_models_keep_state_name_ics_and_refuse_coordinates() -> None:
    """600 states: --ic by state name stays a direct assignment (no dense factorisation)."""
    net = parse_text(_ladder(300))
    prepared = prepare(net, ["v(n300)"], None, ["q(C7)=2e-6", "i(L3)=0.5"])
    full = prepared.full
    assert full.nstates == 600
    assert prepared.x0[full.states.index("q(C7)")] == pytest.approx(2e-6, rel=1e-15)
    assert np.count_nonzero(prepared.x0) == 2
    with pytest.raises(Exception, match="for models of up to 400 states"):
        prepare(net, None, "v(n1),v(n2)")


# --- property: a chain of blocks in positions and velocities is M q'' + D q' + K q = F ----------

from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

CHAIN_RTOL = 1e-9  # relative to each matrix's largest entry: cond(T) reaches ~1e6 for 1e-3 kg beside 1e3 kg


@settings(max_examples=25, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(1e-3, 1e3),  # mass [kg]
            st.floats(1e-1, 1e5),  # spring to the previous block (or the wall) [N/m]
            st.one_of(st.just(0.0), st.floats(1e-3, 1e2)),  # damper beside it [N s/m]; 0 = none
        ),
        min_size=1,
        max_size=3,
    )
)
def test_chain_of_blocks_in_positions_and_velocities(blocks) -> None:
    lines = ["chain"]
    n = len(blocks)
    for j, (m, k, d) in enumerate(blocks, start=1):
        left = "0" if j == 1 else f"b{j - 1}"
        lines += [f"MASS m{j} b{j} {m!r}", f"SPRING k{j} b{j} {left} {k!r}"]
        if d > 0:
            lines.append(f"DAMPER d{j} b{j} {left} {d!r}")
        lines.append(f"FORCE F{j} b{j} 0 DC 1")
    coords = ",".join([f"x(b{j})" for j in range(1, n + 1)] + [f"v(b{j})" for j in range(1, n + 1)])
    change = prepare(parse_text("\n".join(lines) + "\n"), None, coords).change
    M = np.diag([b[0] for b in blocks])
    K, D = np.zeros((n, n)), np.zeros((n, n))
    for j, (_, k, d) in enumerate(blocks):
        for matrix, value in ((K, k), (D, d)):
            matrix[j, j] += value
            if j:
                matrix[j - 1, j - 1] += value
                matrix[j, j - 1] -= value
                matrix[j - 1, j] -= value
    A, B = second_order(M, K, D, np.eye(n))
    np.testing.assert_allclose(change.model.A, A, rtol=0, atol=CHAIN_RTOL * np.abs(A).max())
    # Entries are also right relative to themselves (a damping beside a stiff spring is small:
    # no genuine entry is taken for rounding), and structural zeros are zero to rounding.
    nonzero = A != 0
    np.testing.assert_allclose(change.model.A[nonzero], A[nonzero], rtol=CHAIN_RTOL)
    rows = np.abs(A).max(axis=1, keepdims=True) * np.ones_like(A)
    assert np.all(np.abs(change.model.A[~nonzero]) <= 1e-12 * rows[~nonzero])
    np.testing.assert_allclose(change.model.B, B, rtol=0, atol=CHAIN_RTOL * np.abs(B).max())


def test_voltage_states_as_spice_users_think(tmp_path) -> None:
    """``--coordinates voltage``: capacitor voltages and inductor currents. For the series RLC
    (1 kΩ, 10 µH, 1 nF) the state equations are v' = i/C and i' = (V1 − R i − v)/L, closed forms
    for every entry of A, B; the default outputs stay the node voltages."""
    import numpy as np

    import netlistdyn

    path = tmp_path / "rlc.cir"
    path.write_text("RLC\nV1 in 0 DC 1\nR1 in a 1k\nL1 a out 10u\nC1 out 0 1n\n.end\n")
    model = netlistdyn.compile(path, coordinates="voltage")
    assert model.states == ("v(out)", "i(L1)")
    assert model.outputs == ("v(in)", "v(a)", "v(out)")
    R, L, C = 1e3, 10e-6, 1e-9
    # the change of variables is a diagonal scaling by C: one rounding per entry
    np.testing.assert_allclose(model.A, [[0, 1 / C], [-1 / L, -R / L]], rtol=1e-15, atol=0)
    np.testing.assert_allclose(model.B, [[0], [1 / L]], rtol=1e-15, atol=0)
    np.testing.assert_allclose(model.C[2], [1, 0], rtol=1e-15, atol=0)
    charges = netlistdyn.compile(path)
    assert charges.states == ("q(C1)", "i(L1)")
    assert np.abs(model.A).max() < 1e-4 * np.abs(charges.A).max()  # 1e9 against 1e14
