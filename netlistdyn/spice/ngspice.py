"""The only module that talks to PySpice and ngspice.

A parsed :class:`~netlistdyn.circuit.netlist.Netlist` is translated element by
element into a PySpice ``Circuit`` and run as a transient with zero initial
conditions (``uic``). Each run happens in a child process: PySpice's
shared-library mode keeps every vector and is reported to leak memory run
after run, and only a child process can be stopped at a time limit.

Currents through elements ngspice has no branch current for (R, C, I, G, F)
are measured with a 0 V source in series (the SPICE ammeter), which does
not change the circuit.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import math
import os
import re
import shutil
import subprocess
import tempfile
import time
from collections.abc import Sequence
from ctypes.util import find_library
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from netlistdyn.base.processes import run_in_child, run_in_child_status, run_program
from netlistdyn.circuit.netlist import GROUND, Element, Kind, Netlist
from netlistdyn.circuit.probes import Probe
from netlistdyn.devices.models import DISPLACEMENT
from netlistdyn.devices.registry import REGISTRY
from netlistdyn.devices.traits import SpiceText

INSTALL_HINT = (
    "ngspice is not available: install it with "
    "'apt-get install -y ngspice libngspice0-dev && pip install PySpice'"
)


def _has_branch(element: Element) -> bool:
    """True when ngspice has the element's current as a branch vector (V, L, E, H)."""
    return REGISTRY[element.kind].branch_current


@dataclass(frozen=True, slots=True)
class SpiceSettings:
    """How ngspice is run (its ``.options`` and ``.tran`` arguments).

    Attributes
    ----------
    tstep, tstop : float
        ``.tran`` step and horizon (s). ngspice's first internal step is
        tstep/100, so a small tstep keeps its start-up error small.
    waveform_step : float
        The TSTEP that fills the sources' waveform defaults (s); defaults to
        ``tstep``.
    tmax : float or None
        Maximum internal step (s); ``None`` lets ngspice choose.
    method : str
        ``"trap"`` or ``"gear"``.
    reltol : float
        Relative tolerance.
    abstol, vntol, chgtol : float or None
        Absolute current (A), voltage (V) and charge (C) tolerances;
        ``None`` keeps ngspice's defaults (1e-12, 1e-6, 1e-14).
    """

    tstep: float
    tstop: float
    tmax: float | None = None
    method: str = "trap"
    reltol: float = 1e-3
    abstol: float | None = None
    vntol: float | None = None
    chgtol: float | None = None
    waveform_step: float | None = None
    grid: int = 0  # > 0: force time points at tstop·k/grid (a 0 V PWL source's corners)
    uic: bool = True  # .tran ... uic: no operating point (validate follows the netlist's .tran)

    def describe(self) -> str:
        """The settings as ngspice options, for reports."""
        parts = [f"method={self.method}", f"reltol={self.reltol:g}"]
        for name in ("abstol", "vntol", "chgtol"):
            value = getattr(self, name)
            if value is not None:
                parts.append(f"{name}={value:g}")
        tran = (
            f".tran {self.tstep:g} {self.tstop:g}"
            + (f" 0 {self.tmax:g}" if self.tmax else "")
            + (" uic" if self.uic else "")
        )
        return f"{tran}; .options {' '.join(parts)}"

    def options(self) -> dict[str, Any]:
        """Keyword arguments for PySpice's ``simulator.options``."""
        opts: dict[str, Any] = {"reltol": self.reltol, "method": self.method}
        for name in ("abstol", "vntol", "chgtol"):
            value = getattr(self, name)
            if value is not None:
                opts[name] = value
        return opts


@dataclass(frozen=True)
class SpiceRun:
    """Result of one ngspice transient.

    Attributes
    ----------
    time : numpy.ndarray
        ngspice's own time points (s).
    outputs : dict
        Output name → waveform at ``time``.
    seconds : float
        Wall time of the ngspice run itself (s), without process start-up.
    settings : SpiceSettings
    ok : bool
        False when ngspice failed or did not reach ``tstop``.
    message : str
        ngspice's complaint when it failed (e.g. "timestep too small").
    """

    time: NDArray[np.float64]
    outputs: dict[str, NDArray[np.float64]]
    seconds: float
    settings: SpiceSettings
    ok: bool = True
    message: str = ""
    netlist_text: str = field(default="", repr=False)
    status: str = "ok"  # "ok", "failed" (ngspice ran and refused), "timeout" or "unusable"
    cpu: float = float("nan")  # CPU time of the ngspice process (s), from its resource usage (batch runs)


def ngspice_missing() -> str | None:
    """``None`` when PySpice and libngspice are usable, else how to install them."""
    if importlib.util.find_spec("PySpice") is None:
        return INSTALL_HINT
    if os.environ.get("NGSPICE_LIBRARY_PATH"):
        return None
    if find_library("ngspice") is None and not any(
        os.path.exists(p)
        for p in (
            "/usr/lib/x86_64-linux-gnu/libngspice.so",
            "/usr/lib/aarch64-linux-gnu/libngspice.so",
            "/usr/lib/libngspice.so",
            "/usr/local/lib/libngspice.so",
        )
    ):
        return INSTALL_HINT
    return None


def spice_name(element: Element) -> str:
    """The element's name in the ngspice netlist: its SPICE letter first.

    SPICE elements keep their names; mechanical elements and elements of
    flattened subcircuits become ``<letter>_<keyword>_<name>`` with every
    character ngspice might misread replaced by ``_``.
    """
    letter = REGISTRY[element.kind].letter
    plain = element.name.replace("_", "").isalnum()
    if element.keyword is None and plain and element.name[0].upper() == letter:
        return element.name
    clean = "".join(ch if ch.isalnum() else "_" for ch in element.name)
    return f"{letter}_{(element.keyword or 'x').lower()}_{clean}"


def _sense_name(element: Element) -> str:
    return "Vsense_" + "".join(ch if ch.isalnum() else "_" for ch in element.key)


def build_circuit(
    netlist: Netlist,
    probes: Sequence[Probe],
    waveform_step: float,
    tstop: float,
    ac_source: str | None = None,
) -> Any:
    """Translate a netlist into a PySpice ``Circuit``.

    Parameters
    ----------
    netlist : Netlist
    probes : sequence of Probe
        Current probes on elements without an ngspice branch current get a
        0 V ammeter in series.
    waveform_step, tstop : float
        TSTEP and TSTOP that fill the waveforms' SPICE defaults (PULSE rise
        time...). Every waveform is written out in full, so ngspice sees the
        stimulus the model sees whatever step it is then run with.
    ac_source : str, optional
        Key of a source given ``AC 1`` (ngspice's ``.pz`` needs one).

    Returns
    -------
    PySpice.Spice.Netlist.Circuit
    """
    from PySpice.Spice.Netlist import Circuit  # noqa: PLC0415 (deferred, PySpice: optional spice extra)

    circuit = Circuit(netlist.title or "netlistdyn")
    sensed = {p.element for p in probes if p.kind == "i" and not _has_branch(netlist.element(p.element))}
    for probe in probes:
        if probe.kind == "x":  # displacement: a unit capacitor integrating the velocity
            node = _integrator_node(probe)
            circuit.VCCS(
                f"int_{node}", 0, node, _node(probe.nodes[0]), _node(probe.nodes[1]), transconductance=1
            )
            circuit.C(f"int_{node}", node, 0, 1)
            circuit.R(f"int_{node}", node, 0, 1e30)  # a DC path; time constant 1e30 s
    for node in _displaced_nodes(netlist):  # x(n) read by an expression: the same integrator
        name = _displacement_node(node)
        circuit.VCCS(f"int_{name}", 0, name, _node(node), 0, transconductance=1)
        circuit.C(f"int_{name}", name, 0, 1)
        circuit.R(f"int_{name}", name, 0, 1e30)
    for element in netlist.elements:
        pos, neg = (*element.nodes, "", "")[:2]
        if element.key in sensed:
            middle = _sense_name(element).lower() + "_node"
            circuit.V(_sense_name(element)[1:], middle, neg, 0)
            neg = middle
        _add_element(circuit, element, pos, neg, netlist, (waveform_step, tstop), element.key == ac_source)
    return circuit


def _node(name: str) -> Any:
    return 0 if name == GROUND else name


def _displaced_nodes(netlist: Netlist) -> list[str]:
    """Nodes whose displacement x(n) a behavioural expression reads, in order of appearance."""
    found: dict[str, None] = {}
    for element in netlist.elements:
        if element.kind in (Kind.BVOLTAGE, Kind.BCURRENT) and element.expression:
            for match in re.finditer(r"i\(" + re.escape(DISPLACEMENT) + r"([^)]+)\)", element.expression):
                found.setdefault(match.group(1), None)
    return list(found)


def _displacement_node(node: str) -> str:
    return "xdisp_" + "".join(ch if ch.isalnum() else "_" for ch in node)


def _integrator_node(probe: Probe) -> str:
    return "xint_" + "".join(ch if ch.isalnum() else "_" for ch in probe.name)


def _add_element(
    circuit: Any,
    element: Element,
    pos: str,
    neg: str,
    netlist: Netlist,
    span: tuple[float, float],
    ac: bool = False,
) -> None:
    """Write ``element`` into ``circuit`` as its device's writer does (``DeviceKind.spice``)."""
    write = REGISTRY[element.kind].spice
    if write is None:
        raise NotImplementedError(f"{element.label}: no ngspice translation for {element.kind.name}")
    text = SpiceText(
        spice_name(element)[1:],  # PySpice adds the letter
        _node(pos),
        _node(neg),
        lambda key: spice_name(netlist.element(key)),
        lambda expression: _expression_text(expression, netlist),
        _node,
        span,
        ac,
    )
    write(circuit, element, text)


def _expression_text(text: str, netlist: Netlist) -> str:
    """A folded expression in ngspice's names (elements, ground, displacement integrators)."""
    text = re.sub(
        r"i\(" + re.escape(DISPLACEMENT) + r"([^)]+)\)",
        lambda m: f"v({_displacement_node(m.group(1))})",
        text,
    )
    text = re.sub(r"i\(([^)]+)\)", lambda m: f"i({spice_name(netlist.element(m.group(1)))})", text)
    return re.sub(
        r"v\(([^)]+)\)",
        lambda m: "v(" + ",".join("0" if a == GROUND else a for a in m.group(1).split(",")) + ")",
        text,
    )


def _vector(analysis: Any, probe: Probe, netlist: Netlist) -> NDArray[np.float64]:
    if probe.kind == "v":
        a, b = probe.nodes
        va = np.asarray(analysis.nodes[a], dtype=float) if a != GROUND else 0.0
        vb = np.asarray(analysis.nodes[b], dtype=float) if b != GROUND else 0.0
        return np.asarray(va - vb, dtype=float) * np.ones(len(analysis.time))
    if probe.kind == "x":
        return np.asarray(analysis.nodes[_integrator_node(probe)], dtype=float)
    element = netlist.element(probe.element)
    if _has_branch(element):
        current = np.asarray(analysis.branches[spice_name(element).lower()], dtype=float)
    else:
        current = np.asarray(analysis.branches[_sense_name(element).lower()], dtype=float)
    if probe.kind == "angle":
        assert element.rod is not None
        return current * (-element.value / element.rod.length)
    return current


def _child(conn: Any, netlist: Netlist, probes: Sequence[Probe], settings: SpiceSettings) -> None:
    """Run in the child process: simulate and send back a plain dict."""
    logging.disable(logging.CRITICAL)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)  # ngspice's own banner and notes would otherwise reach our stdout
    os.dup2(devnull, 2)
    result: dict[str, Any] = {"ok": False, "message": "", "time": np.zeros(0), "outputs": {}, "seconds": 0.0}
    try:
        circuit = build_circuit(netlist, probes, settings.waveform_step or settings.tstep, settings.tstop)
        if settings.grid:
            # ngspice lands a step on every source breakpoint: a 0 V PWL source with a corner
            # at each grid time puts those times in the output, with no interpolation.
            corners = " ".join(f"{settings.tstop * k / settings.grid!r} 0" for k in range(settings.grid + 1))
            circuit.V("netlistdyn_grid", "netlistdyn_grid", 0, f"PWL({corners})")
            circuit.R("netlistdyn_grid", "netlistdyn_grid", 0, 1)
        simulator = circuit.simulator(simulator="ngspice-shared")
        tolerate_notes(simulator)
        simulator.options(**settings.options())
        if netlist.initial_conditions:
            simulator.initial_condition(**{_node(ic.node): ic.value for ic in netlist.initial_conditions})
        result["netlist_text"] = str(simulator)
        start = time.perf_counter()
        try:
            analysis = simulator.transient(
                step_time=settings.tstep,
                end_time=settings.tstop,
                max_time=settings.tmax,
                use_initial_condition=settings.uic,
            )
        finally:
            result["seconds"] = time.perf_counter() - start
        stderr = " ".join(str(x) for x in _collect_stderr(simulator))
        t = np.asarray(analysis.time, dtype=float)
        result["time"] = t
        result["outputs"] = {p.name: _vector(analysis, p, netlist) for p in probes}
        reached = t.size > 0 and t[-1] >= settings.tstop * (1 - 1e-9)
        result["ok"] = bool(reached)
        if not reached:
            stopped = t[-1] if t.size else 0.0
            result["message"] = _failure_message(stderr) or f"ngspice stopped at t={stopped:g} s"
    except Exception as exc:
        stderr = " ".join(str(x) for x in _collect_stderr(locals().get("simulator")))
        result["message"] = _failure_message(stderr) or f"{type(exc).__name__}: {exc}"
        if "simulator" not in locals() and unusable_reason(exc):
            result["status"] = "unusable"
            result["message"] = unusable_reason(exc)
    with contextlib.suppress(Exception):
        conn.send(result)
    conn.close()


#: ngspice's stderr lines that inform rather than fail ("Note: v1: has no value, DC 0 assumed").
INFORMATIONAL_PREFIXES = ("note:", "warning:")


def only_informational(lines: Sequence[str]) -> bool:
    """True when every non-blank stderr line of ngspice is a note or a warning."""
    return all(not line.strip() or line.strip().lower().startswith(INFORMATIONAL_PREFIXES) for line in lines)


def tolerate_notes(simulator: Any) -> None:
    """Make PySpice treat ngspice's informational stderr lines as what they are.

    PySpice's shared-library wrapper marks every stderr line that is not a
    "Warning:" as an error and fails the command (``Note: ...`` lines, printed
    for instance for a source with both a DC value and a PULSE, never give a
    result). A command that failed only with such lines is taken as
    successful; real errors (on stdout, or any other stderr line) still fail.
    """
    ngspice = getattr(simulator, "ngspice", None)
    original = getattr(ngspice, "exec_command", None)
    if ngspice is None or original is None:
        return
    from PySpice.Spice.NgSpice.Shared import NgSpiceCommandError  # noqa: PLC0415 (deferred, PySpice: optional spice extra)

    def exec_command(command: str, join_lines: bool = True) -> Any:
        try:
            return original(command, join_lines)
        except NgSpiceCommandError:
            if getattr(ngspice, "_error_in_stdout", True) or not only_informational(ngspice._stderr):
                raise
            return ngspice.stdout if join_lines else list(ngspice._stdout)

    ngspice.exec_command = exec_command


def unusable_reason(exc: BaseException) -> str:
    """Why ngspice cannot be used at all ("" when ``exc`` is about this netlist).

    An import error (PySpice or its dependencies) or an :class:`OSError` while
    the shared library is loaded means no netlist can be validated.
    """
    if isinstance(exc, ImportError):
        return f"ngspice unusable: PySpice cannot be imported ({' '.join(str(exc).split())[:160]})"
    if isinstance(exc, OSError):
        return f"ngspice unusable: libngspice cannot be loaded ({' '.join(str(exc).split())[:160]})"
    return ""


def _collect_stderr(simulator: Any) -> list[str]:
    if simulator is None:
        return []
    try:
        return list(simulator.ngspice.stderr)
    except Exception:
        return []


def _failure_message(stderr: str) -> str:
    low = stderr.lower()
    if "timestep too small" in low:
        return "ngspice: timestep too small"
    if "singular matrix" in low:
        return "ngspice: singular matrix"
    for line in stderr.split("Error"):
        if line.strip():
            return "ngspice error:" + line.strip()[:200] if "error" in low else ""
    return ""


def run_transient(
    netlist: Netlist, probes: Sequence[Probe], settings: SpiceSettings, timeout: float | None = None
) -> SpiceRun:
    """Simulate ``netlist`` in ngspice and return the probed waveforms.

    Parameters
    ----------
    netlist : Netlist
    probes : sequence of Probe
    settings : SpiceSettings
    timeout : float, optional
        Seconds after which the ngspice process is killed.

    Returns
    -------
    SpiceRun
        ``ok`` is False (with a message) when ngspice failed or timed out.
    """
    result, how = run_in_child_status(_child, (netlist, list(probes), settings), timeout)
    if result is None:
        if how == "timeout":
            message = f"ngspice did not finish within {timeout:g} s"
            return SpiceRun(
                np.zeros(0), {}, float(timeout or 0.0), settings, False, message, status="timeout"
            )
        message = "ngspice unusable: its process died before answering (a crash of libngspice)"
        return SpiceRun(np.zeros(0), {}, 0.0, settings, False, message, status="unusable")
    status = result.get("status", "ok" if result["ok"] else "failed")
    return SpiceRun(
        result["time"],
        result["outputs"],
        result["seconds"],
        settings,
        result["ok"],
        result["message"],
        result.get("netlist_text", ""),
        status,
    )


def batch_missing() -> str | None:
    """``None`` when batch ngspice can run (the ``ngspice`` program, PySpice to write the deck)."""
    if importlib.util.find_spec("PySpice") is None or shutil.which("ngspice") is None:
        return INSTALL_HINT
    return None


class _Table:
    """ngspice's vectors read back from ``wrdata``, shaped as PySpice's analysis (for :func:`_vector`)."""

    def __init__(self, time: NDArray[np.float64], nodes: dict[str, Any], branches: dict[str, Any]) -> None:
        self.time = time
        self.nodes = nodes
        self.branches = branches


def _batch_vectors(netlist: Netlist, probes: Sequence[Probe]) -> tuple[list[str], list[str]]:
    """Node names and branch names (lower case) that the probes read."""
    nodes: list[str] = []
    branches: list[str] = []
    for probe in probes:
        if probe.kind == "v":
            nodes += [n for n in probe.nodes if n != GROUND]
        elif probe.kind == "x":
            nodes.append(_integrator_node(probe))
        else:
            element = netlist.element(probe.element)
            name = spice_name(element) if _has_branch(element) else _sense_name(element)
            branches.append(name.lower())
    return list(dict.fromkeys(nodes)), list(dict.fromkeys(branches))


def batch_deck(netlist: Netlist, probes: Sequence[Probe], settings: SpiceSettings, data: str) -> str:
    """The deck run by :func:`run_batch`: the circuit, its options, and a control block writing ``data``."""
    previous = logging.root.manager.disable
    logging.disable(logging.WARNING)  # PySpice warns about node names such as "in"; ngspice reads them
    try:
        circuit = build_circuit(netlist, probes, settings.waveform_step or settings.tstep, settings.tstop)
        text = str(circuit).rstrip("\n")
    finally:
        logging.disable(previous)
    lines = [text]
    if settings.grid:
        # ngspice lands a step on every source breakpoint: a 0 V PWL source with a corner
        # at each grid time puts those times in the output, with no interpolation.
        corners = " ".join(f"{settings.tstop * k / settings.grid!r} 0" for k in range(settings.grid + 1))
        lines += [
            f"Vnetlistdyn_grid netlistdyn_grid 0 PWL({corners})",
            "Rnetlistdyn_grid netlistdyn_grid 0 1",
        ]
    lines.append(".options " + " ".join(f"{k}={v}" for k, v in settings.options().items()))
    nodes, branches = _batch_vectors(netlist, probes)
    vectors = [f"v({n})" for n in nodes] + [f"{b}#branch" for b in branches]
    lines.append(".save " + " ".join(vectors))
    tmax = f" 0 {settings.tmax!r}" if settings.tmax else ""
    lines += [
        ".control",
        "set wr_singlescale",
        "set wr_vecnames",
        "option numdgt=16",
        f"tran {settings.tstep!r} {settings.tstop!r}{tmax} uic",
        f"wrdata {data} " + " ".join(vectors),
        "quit",
        ".endc",
        ".end",
    ]
    return "\n".join(lines) + "\n"


def run_batch(
    netlist: Netlist,
    probes: Sequence[Probe],
    settings: SpiceSettings,
    timeout: float | None = None,
    cpu_limit: float | None = None,
) -> SpiceRun:
    """Run ngspice in batch mode (``ngspice -b``), as a user would, and read the probed waveforms.

    Unlike :func:`run_transient` (PySpice's shared library, which keeps every
    vector), only the probed vectors are saved, and the CPU and wall times
    are the ngspice process's own (its resource usage; the wall time includes
    reading the deck). Used by ``bench``.

    Parameters
    ----------
    netlist : Netlist
    probes : sequence of Probe
    settings : SpiceSettings
    timeout : float, optional
        Seconds of wall time after which ngspice is killed.
    cpu_limit : float, optional
        Seconds of ngspice's own CPU time (``RLIMIT_CPU``, whole seconds, at least 1) after
        which it is stopped: a measure a loaded machine does not stretch.

    Returns
    -------
    SpiceRun
        ``status`` "ok", "failed", "timeout" (wall or CPU time ran out: the message says
        which) or "unusable"; ``seconds`` is the wall time, ``cpu`` the CPU time.
    """

    binary = shutil.which("ngspice")
    if binary is None:
        return SpiceRun(np.zeros(0), {}, 0.0, settings, False, INSTALL_HINT, status="unusable")
    with tempfile.TemporaryDirectory(prefix="netlistdyn-batch") as tmp:
        data = os.path.join(tmp, "out.txt")
        deck = batch_deck(netlist, probes, settings, data)
        with open(os.path.join(tmp, "deck.cir"), "w", encoding="utf-8") as handle:
            handle.write(deck)
        limit = None if cpu_limit is None else max(1.0, math.ceil(cpu_limit))
        run = run_program([binary, "-b", "deck.cir"], timeout, cwd=tmp, cpu_limit=limit)
        table = np.zeros((0, 1))
        if run.how == "ok" and os.path.exists(data):
            with contextlib.suppress(ValueError):
                table = np.atleast_2d(np.loadtxt(data, skiprows=1, ndmin=2))
    fail = SpiceRun(np.zeros(0), {}, run.wall, settings, False, "", deck, "failed", run.cpu)
    if run.how == "timeout":
        return replace(fail, message=f"ngspice did not finish within {timeout:g} s", status="timeout")
    if run.how == "cpu limit":
        return replace(fail, message=f"ngspice's CPU time ran out ({run.cpu:.3g} s)", status="timeout")
    if run.how == "missing":
        return replace(fail, message=f"ngspice cannot be started: {run.stderr}", status="unusable")
    nodes, branches = _batch_vectors(netlist, probes)
    t = table[:, 0] if table.shape[1] == 1 + len(nodes) + len(branches) else np.zeros(0)
    if t.size == 0 or t[-1] < settings.tstop * (1 - 1e-9):
        stopped = f"ngspice stopped at t={t[-1]:g} s" if t.size else "ngspice wrote no result"
        return replace(fail, message=_failure_message(run.stdout + run.stderr) or stopped)
    columns = iter(table[:, 1:].T)
    view = _Table(t, {n: next(columns) for n in nodes}, {b: next(columns) for b in branches})
    outputs = {p.name: _vector(view, p, netlist) for p in probes}
    return SpiceRun(t, outputs, run.wall, settings, True, "", deck, "ok", run.cpu)


@dataclass(frozen=True)
class PoleZeroRun:
    """Poles from ngspice's ``.pz`` analysis (1/s)."""

    poles: NDArray[np.complex128]
    ok: bool
    message: str = ""


def _pz_child(conn: Any, netlist: Netlist, ports: tuple[str, str, str, str], kind: str, source: str) -> None:
    logging.disable(logging.CRITICAL)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    result: dict[str, Any] = {"ok": False, "poles": np.zeros(0, dtype=complex), "message": ""}
    try:
        circuit = build_circuit(netlist, (), 1.0, 1.0, ac_source=source)
        simulator = circuit.simulator(simulator="ngspice-shared")
        tolerate_notes(simulator)
        analysis = simulator.polezero(*(_node(n) for n in ports), kind, "pol")
        poles = [complex(np.asarray(v).ravel()[0]) for k, v in analysis.nodes.items() if k.startswith("pole")]
        result.update(ok=True, poles=np.asarray(poles, dtype=complex))
    except Exception:  # reported, not raised
        result["message"] = "ngspice's .pz analysis failed (it often does with a pole at 0 or unstable poles)"
    with contextlib.suppress(Exception):
        conn.send(result)
    conn.close()


def run_polezero(netlist: Netlist, output: tuple[str, str], timeout: float = 60.0) -> PoleZeroRun:
    """ngspice ``.pz`` poles of the transfer function from the first source to ``output``.

    Parameters
    ----------
    netlist : Netlist
    output : tuple of str
        Output node pair.
    timeout : float
        Seconds allowed.
    """
    if not netlist.sources:
        return PoleZeroRun(np.zeros(0, dtype=complex), False, "no independent source to excite")
    source = netlist.sources[0]
    kind = "vol" if source.kind is Kind.VSOURCE else "cur"
    ports = (source.nodes[0], source.nodes[1], output[0], output[1])
    result = run_in_child(_pz_child, (netlist, ports, kind, source.key), timeout)
    if result is None:
        return PoleZeroRun(np.zeros(0, dtype=complex), False, "ngspice .pz did not finish")
    return PoleZeroRun(result["poles"], result["ok"], result["message"])


# ---------------------------------------------------------------------------
# The user's original file, as ngspice itself reads it (validate's check for
# misreadings). Everything above feeds ngspice the netlist as netlistdyn
# understood it, which cannot reveal a parse-level misunderstanding; this runs
# the ngspice binary on the file the user wrote.


@dataclass(frozen=True)
class OriginalRun:
    """ngspice's ``op`` and ``ac`` on the user's original netlist file.

    Attributes
    ----------
    ok : bool
        False when ngspice could not read or run the file.
    message : str
        ngspice's first complaint when it failed.
    op : dict
        Vector name (``v(out)``, ``i(v1)``, lower case) → operating-point value;
        empty when ngspice's ``op`` failed (a singular DC matrix).
    ac : dict
        Frequency (Hz) → {vector name → complex phasor}.
    """

    ok: bool
    message: str = ""
    op: dict[str, float] = field(default_factory=dict)
    ac: dict[float, dict[str, complex]] = field(default_factory=dict)


def ngspice_source_name(name: str) -> str:
    """ngspice's instance name of a netlistdyn element name (``X1.Vs`` → ``v.x1.vs``)."""
    low = name.lower()
    if "." not in low:
        return low
    return f"{low.rsplit('.', 1)[1][0]}.{low}"


def _without_control_blocks(text: str) -> str:
    kept, inside = [], False
    for line in text.splitlines():
        word = line.strip().lower()
        if word.startswith(".control"):
            inside = True
        elif inside and word.startswith(".endc"):
            inside = False
        elif not inside:
            kept.append(line)
    return "\n".join(kept) + "\n"


def _read_ascii_raw(path: str) -> list[dict[str, NDArray[np.complex128]]]:
    """The plots of an ngspice ASCII rawfile, each {vector name → values}."""
    with open(path, encoding="utf-8", errors="replace") as handle:
        lines = [ln for ln in handle.read().splitlines() if ln.strip()]
    plots, i = [], 0
    while i < len(lines):
        if not lines[i].startswith("Title:"):
            i += 1
            continue
        nvars = npoints = 0
        while not lines[i].startswith("Variables:"):
            key, _, val = lines[i].partition(":")
            if key == "No. Variables":
                nvars = int(val)
            elif key == "No. Points":
                npoints = int(val)
            i += 1
        names = [lines[i + 1 + k].split()[1].lower() for k in range(nvars)]
        i += nvars + 2
        data = np.zeros((npoints, nvars), dtype=complex)
        for p in range(npoints):
            for v in range(nvars):
                re_part, _, im_part = lines[i].split()[-1].partition(",")
                data[p, v] = complex(float(re_part), float(im_part or 0.0))
                i += 1
        plots.append({n: data[:, k] for k, n in enumerate(names)})
    return plots


def run_original(
    path: str,
    sources: Sequence[tuple[str, float | None, float]],
    frequencies: Sequence[float],
    params: dict[str, float] | None = None,
    timeout: float = 60.0,
    separate: bool = False,
    with_op: bool = True,
    options: str = "",
) -> OriginalRun:
    """Run the ngspice binary on the user's file: ``op`` and ``ac`` with chosen source values.

    Parameters
    ----------
    path : str
        The netlist file exactly as the user wrote it (``.control`` blocks are
        removed from a temporary copy so that its own analyses do not run).
    sources : sequence of (str, float, float)
        ngspice instance name of every independent source, its DC value (V or
        A; ``None``: the file's own) and its AC magnitude, set with ``alter`` before the analyses.
    frequencies : sequence of float
        ``ac`` frequencies (Hz).
    params : dict, optional
        ``.param`` overrides, applied with ``alterparam`` and ``reset``.
    timeout : float
        Seconds allowed to ngspice (per session).
    separate : bool
        Each analysis in its own ngspice session: ngspice 39 applies a diode's ``m=`` once more
        at each further analysis of a session (measured), so a nonlinear file needs this.
    with_op : bool
        Run ``op`` (before the ``ac`` analyses).
    options : str
        ngspice ``option`` settings for the analyses (``reltol=1e-9 ...``); empty: the file's.

    Returns
    -------
    OriginalRun
    """

    if separate and frequencies:
        first = run_original(path, sources, frequencies[:1], params, timeout, options=options)
        if not first.ok:
            return first
        merged: dict[float, dict[str, complex]] = {}
        for f in frequencies:
            alone = run_original(path, sources, [f], params, timeout, with_op=False, options=options)
            if not alone.ok:
                return alone
            merged.update(alone.ac)
        return OriginalRun(True, "", first.op, merged)

    binary = shutil.which("ngspice")
    if binary is None:
        return OriginalRun(False, "the ngspice program is not on PATH")
    source = os.path.abspath(path)
    with tempfile.TemporaryDirectory(prefix="netlistdyn-orig") as tmp:
        with open(source, "rb") as handle:
            raw = handle.read().decode("latin-1")
        deck = source
        if re.search(r"^\s*\.control", raw, re.IGNORECASE | re.MULTILINE):
            deck = os.path.join(tmp, os.path.basename(source))
            with open(deck, "wb") as handle:
                handle.write(_without_control_blocks(raw).encode("latin-1"))
        cmds = [f"alterparam {k}={v:.17g}" for k, v in (params or {}).items()]
        if params:
            cmds.append("reset")
        for name, dc, acmag in sources:
            if dc is not None:
                cmds.append(f"alter @{name}[dc]={dc:.17g}")
            cmds.append(f"alter @{name}[acmag]={acmag:.17g}")
        if options:
            cmds.append(f"option {options}")
        cmds += ["set filetype=ascii", *(("op", f"write {tmp}/op.raw") if with_op else ())]
        for k, f in enumerate(frequencies):
            cmds += [f"ac lin 1 {f:.17g} {f:.17g}", f"write {tmp}/ac{k}.raw"]
        script = "\n".join([*cmds, "quit", ""])
        try:
            proc = subprocess.run(
                [binary, "-n", "-p", deck],
                input=script.encode(),
                capture_output=True,
                timeout=timeout,
                cwd=os.path.dirname(source),
            )
        except subprocess.TimeoutExpired:
            return OriginalRun(False, f"ngspice did not finish within {timeout:g} s")
        text = (proc.stdout + proc.stderr).decode("utf-8", "replace")
        complaints = [
            ln.strip()
            for ln in text.splitlines()
            if ln.strip().lower().startswith(("error", "fatal")) and "graphics" not in ln
        ]
        op: dict[str, float] = {}
        if os.path.exists(f"{tmp}/op.raw"):
            plots = _read_ascii_raw(f"{tmp}/op.raw")
            if plots:
                op = {k: float(v[0].real) for k, v in plots[0].items()}
        ac: dict[float, dict[str, complex]] = {}
        for k, f in enumerate(frequencies):
            if os.path.exists(f"{tmp}/ac{k}.raw"):
                plots = _read_ascii_raw(f"{tmp}/ac{k}.raw")
                if plots:
                    ac[f] = {n: complex(v[0]) for n, v in plots[0].items() if n != "frequency"}
    if "Numparam expansion errors" in text:
        return OriginalRun(False, "ngspice reports numparam expansion errors")
    if not ac:
        return OriginalRun(False, complaints[0] if complaints else "ngspice's ac produced nothing")
    return OriginalRun(True, "", op, ac)
