"""Large circuits: when to use the sparse descriptor form, and the CLI glue for it.

The explicit model ``x' = A x + B u`` eliminates every node without a
capacitor; in a mesh (a power grid) that elimination fills ``A`` densely
(a 2500-state grid took 5 GB). Above :data:`DESCRIPTOR_UNKNOWNS` MNA
unknowns, ``simulate --method auto`` and ``analyze`` work on the sparse
descriptor form (:mod:`netlistdyn.descriptor`, :mod:`netlistdyn.transient`)
instead; ``simulate --method descriptor`` forces it at any size.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse.linalg as spla

from netlistdyn.base.errors import NetlistError, UsageError
from netlistdyn.base.values import parse_number
from netlistdyn.circuit.netlist import Kind, Netlist
from netlistdyn.circuit.sources import SourceValues, source_waveform
from netlistdyn.circuit.waveforms import check_breakpoints
from netlistdyn.devices.registry import REGISTRY
from netlistdyn.devices.units import signal_units
from netlistdyn.formulation.descriptor import DescriptorSystem, assemble, supports
from netlistdyn.formulation.formulate import state_name, tree_candidates
from netlistdyn.simulation.foh import Horizon
from netlistdyn.simulation.initial import descriptor_start, uses_uic
from netlistdyn.simulation.transient import (
    CF_CHECK_DEGREE,
    CF_DEGREE,
    DEFAULT_METHOD,
    DEFAULT_ORDER,
    _lu,
    run_transient,
)
from netlistdyn.workflows.pipelines import Simulation

if TYPE_CHECKING:
    from netlistdyn.simulation.foh import Horizon

#: Above this many MNA unknowns, ``auto`` uses the descriptor form.
DESCRIPTOR_UNKNOWNS = 5000


def unknown_count(netlist: Netlist) -> int:
    """Number of MNA unknowns: nodes plus the currents of L, V, E and H elements."""
    branches = sum(1 for e in netlist.elements if REGISTRY[e.kind].branch_current)
    return len(netlist.nodes) + branches


def descriptor_wanted(netlist: Netlist, method: str) -> bool:
    """True for ``--method descriptor``, or ``auto`` on a large circuit the descriptor form supports."""
    if method == "descriptor":
        return True
    return method == "auto" and supports(netlist) and unknown_count(netlist) > DESCRIPTOR_UNKNOWNS


#: ``simulate --method auto`` takes the descriptor (CF) stepping when the circuit's fastest rate,
#: estimated as below, times the output step exceeds this: the CF approximant is accurate on the
#: whole negative real axis, so it takes one step per output interval whatever the stiffness,
#: where ``rational`` (Padé) resolves the fast modes the input's corners excite (30x30 RC grid,
#: rate·step ≈ 2e4: CF 2.2 s, rational 29 s CPU). An RLC ladder's rows have no such rate (its
#: modes are LC oscillations, which CF does not resolve): it stays with ``rational``.
STIFF_STEP_RATIO = 100.0


def stiffness_ratio(system: DescriptorSystem, tstep: float) -> float:
    """A cheap estimate of max |λ| · ``tstep`` of the pencil (A, E): max over dynamic rows of
    |A_ii| / E_ii (for an RC network, symmetric, the Rayleigh quotient of a unit vector: a lower
    bound on the largest rate)."""
    e = system.E.diagonal()
    a = np.abs(system.A.diagonal())
    dynamic = e > 0
    if not np.any(dynamic):
        return 0.0
    return float(np.max(a[dynamic] / e[dynamic])) * tstep


def simulate_descriptor_wanted(
    netlist: Netlist,
    method: str,
    outputs: Sequence[str] | None,
    tstop: float | None,
    tstep: float | None,
    states_limit: int,
) -> bool:
    """Whether ``simulate`` uses the descriptor form: as :func:`descriptor_wanted`, and for
    ``auto`` also when the circuit is stiff relative to its output step (:data:`STIFF_STEP_RATIO`,
    :func:`stiffness_ratio`), has more than ``states_limit`` reactive elements (below, the dense
    ``exact`` method wins), a horizon (``tstop`` or a ``.tran``), piecewise-linear sources and
    outputs the descriptor form gives."""
    if descriptor_wanted(netlist, method):
        return True
    if method != "auto" or not supports(netlist) or (tstop is None and netlist.tran is None):
        return False
    reactive = sum(1 for e in netlist.elements if e.kind in (Kind.CAPACITOR, Kind.INDUCTOR))
    if reactive <= states_limit:
        return False
    horizon = descriptor_horizon(netlist, tstop, tstep)
    waves = [source_waveform(e).resolved(horizon.tstep, horizon.tstop) for e in netlist.sources]
    if not SourceValues(waves).piecewise_linear():
        return False
    try:
        system = assemble(netlist, outputs)
    except (UsageError, NetlistError):
        return False
    return stiffness_ratio(system, horizon.tstep) > STIFF_STEP_RATIO


def _initial_unknowns(system: DescriptorSystem, ics: Sequence[str]) -> np.ndarray | None:
    if not ics:
        return None
    x0 = np.zeros(system.size)
    index = {name.lower(): k for k, name in enumerate(system.variables)}
    for item in ics:
        name, sep, text = item.partition("=")
        value = parse_number(text.strip()) if sep else None
        key = name.strip().lower()
        if value is None or key not in index:
            raise UsageError(
                f"--ic {item!r}: in the descriptor form the initial values are node voltages v(node) and "
                "branch currents i(L), i(V) (e.g. v(n1)=0.5)"
            )
        x0[index[key]] = value
    return x0


def descriptor_horizon(netlist: Netlist, tstop: float | None, tstep: float | None) -> Horizon:
    """The horizon of a descriptor-form run: ``--tstop``/``--tstep``, else the netlist's ``.tran``.

    Raises
    ------
    UsageError
        A non-positive ``tstop``/``tstep``, or neither a ``--tstop`` nor a ``.tran``.
    """
    for value, flag in ((tstop, "--tstop"), (tstep, "--tstep")):
        if value is not None and not value > 0:
            raise UsageError(f"{flag} must be positive")
    if tstop is not None:
        return Horizon(tstep or tstop / 1000, tstop, "command line")
    if netlist.tran is not None:
        return Horizon(tstep or netlist.tran.tstep, netlist.tran.tstop, ".tran in the netlist")
    raise UsageError("the descriptor form needs a horizon: give --tstop (or a .tran in the netlist)")


def simulate_large(
    netlist: Netlist,
    outputs: Sequence[str] | None,
    tstop: float | None,
    tstep: float | None,
    ics: Sequence[str],
    progress: Callable[[float], None] | None = None,
    rtol: float = 1e-10,
    warn: Callable[[Any], None] | None = None,
) -> Any:
    """Run ``simulate`` on the descriptor form.

    Parameters
    ----------
    netlist : Netlist
    outputs : sequence of str, optional
        Output specifications (default: every node voltage).
    tstop, tstep : float, optional
        Horizon and output step (s); default the netlist's ``.tran``.
    ics : sequence of str
        ``--ic NAME=VALUE`` on descriptor unknowns (implies UIC).
    progress : callable, optional
        Fraction-done callback.
    rtol : float
        Step check tolerance (see :func:`netlistdyn.simulation.transient.run_transient`).
    warn : callable, optional
        Receives each warning (an ``IC=`` that does not apply without ``UIC``).

    The start follows ngspice's rules as the explicit model does (:mod:`netlistdyn.initial`):
    the DC operating point, with ``.ic`` node voltages held during it; under ``UIC`` the
    ``IC=`` and ``.ic`` values, else zero; ``ics`` replaces all of this.

    Returns
    -------
    netlistdyn.api.Simulation
        With the horizon; ``stats`` holds the step counts and CPU seconds.
    """

    horizon = descriptor_horizon(netlist, tstop, tstep)
    count = round(horizon.tstop / horizon.tstep)
    if count > 10_000_000:
        raise UsageError(f"{count} output points: choose a larger --tstep")
    system = assemble(netlist, outputs)
    times = np.linspace(0.0, horizon.tstop, count + 1)
    waves = [source_waveform(e).resolved(horizon.tstep, horizon.tstop) for e in netlist.sources]
    check_breakpoints(
        [(e.name, e.loc, w) for e, w in zip(netlist.sources, waves, strict=True)], horizon.tstop
    )
    uic = uses_uic(netlist)
    x0 = _initial_unknowns(system, ics)
    start = "given unknowns"
    if x0 is None:  # the netlist's own IC= and .ic, by ngspice's rules (netlistdyn.initial)
        u0 = np.array([float(np.asarray(w(np.array([0.0])))[0]) for w in waves])
        x0, start, warnings = descriptor_start(netlist, system, outputs, u0)
        if warn is not None:
            for warning in warnings:
                warn(warning)
    started = time.process_time()
    run = run_transient(system, waves, times, x0, uic=uic, rtol=rtol, where=netlist.path, progress=progress)
    cpu = time.process_time() - started
    if DEFAULT_METHOD in ("cf", "auto"):
        scheme = f"CF rational of degree {CF_DEGREE} on (-inf, 0], checked against degree {CF_CHECK_DEGREE}"
    else:
        scheme = f"Padé [{DEFAULT_ORDER - 1}/{DEFAULT_ORDER}]"
    if run.stats.get("fallback_steps"):
        pade = f"Padé [{DEFAULT_ORDER - 1}/{DEFAULT_ORDER}]"
        scheme += f" ({pade} from the first step where CF's check failed and Padé's passed)"
    stats = {**run.stats, "cpu_seconds": cpu, "unknowns": system.size}
    return Simulation(
        title=netlist.title,
        time=times,
        values=run.outputs,
        outputs=system.outputs,
        units=signal_units(netlist, system.outputs),
        method="descriptor",
        setting=f"{scheme}, rtol={rtol:g}, from the {start}",
        seconds=run.stats["seconds"],
        status=run.status,
        message=run.message,
        horizon=horizon,
        stats=stats,
        start=start,
    )


def analyze_large(netlist: Netlist, outputs: Sequence[str] | None) -> dict[str, Any]:
    """What ``analyze`` reports for a circuit compiled to the descriptor form.

    The states (``q(C)`` of tree capacitors, ``i(L)`` of link inductors: the
    order of complexity, as the explicit model would have them), the size of
    the descriptor system, and its slowest modes (shift-invert Arnoldi at 0
    on the pencil, which needs one sparse LU of ``A``).
    """
    system = assemble(netlist, outputs)
    circuit, tree = tree_candidates(netlist)[0]
    states = [
        state_name(b.element)
        for b in circuit.branches
        if (b.element.kind is Kind.CAPACITOR and tree.in_tree[b.index])
        or (b.element.kind is Kind.INDUCTOR and not tree.in_tree[b.index])
    ]
    states.sort(key=lambda s: not s.startswith("q("))
    slow = slowest_modes(system)
    return {
        "form": "descriptor",
        "title": netlist.title,
        "unknowns": system.size,
        "nodes": system.nnodes,
        "branch_currents": system.size - system.nnodes,
        "dynamic_rows": system.dynamic,
        "nnz": {"E": int(system.E.nnz), "A": int(system.A.nnz), "B": int(system.B.nnz)},
        "nstates": len(states),
        "states": states,
        "inputs": list(system.inputs),
        "outputs": list(system.outputs),
        "slowest_eigenvalues": [[float(v.real), float(v.imag)] for v in slow],
    }


def slowest_modes(system: DescriptorSystem, count: int = 6) -> np.ndarray:
    """The finite eigenvalues of ``(A, E)`` nearest 0 (1/s), by Arnoldi on ``A⁻¹E``."""
    if system.dynamic <= count + 1:
        return np.zeros(0, dtype=complex)
    try:
        lu = _lu(system.A)
    except RuntimeError:
        return np.zeros(0, dtype=complex)
    E = system.E.tocsr()
    op = spla.LinearOperator(system.A.shape, matvec=lambda v: lu.solve(E @ v), dtype=float)
    try:
        mu = spla.eigs(op, k=count, which="LM", return_eigenvectors=False, tol=1e-10)
    except (spla.ArpackNoConvergence, spla.ArpackError):
        return np.zeros(0, dtype=complex)
    mu = mu[np.abs(mu) > 0]
    return np.sort_complex(1.0 / mu)[::-1]


def analyze_text(report: dict[str, Any]) -> str:
    """Plain-text form of :func:`analyze_large`'s report."""
    states = report["states"]
    shown = ", ".join(states[:8]) + (f", ... ({len(states) - 8} more)" if len(states) > 8 else "")
    lines = [
        report["title"],
        f"sparse descriptor form E x' = A x + B u: {report['unknowns']} unknowns "
        f"({report['nodes']} node voltages, {report['branch_currents']} branch currents), "
        f"{report['dynamic_rows']} dynamic rows; "
        f"nnz(E) = {report['nnz']['E']}, nnz(A) = {report['nnz']['A']}",
        f"states ({report['nstates']}): {shown}",
        f"inputs: {len(report['inputs'])}, outputs: {len(report['outputs'])}",
        "(the explicit A, B, C, D are not formed for a circuit of this size: eliminating the nodes "
        "without a capacitor would fill A)",
    ]
    if report["slowest_eigenvalues"]:
        lines.append("slowest eigenvalues (shift-invert Arnoldi at 0):")
        for re, im in report["slowest_eigenvalues"]:
            tau = f"{-1.0 / re:.6g}" if re < 0 else "-"
            lines.append(f"  {re:>16.9g} {im:>+16.9g}j   tau [s] {tau}")
    return "\n".join(lines) + "\n"
