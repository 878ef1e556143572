"""The Python API: the command line's pipelines as functions returning typed results.

Every function takes the netlist as a path, as netlist text, or as an open
file (``io.StringIO``), and ``params`` as numbers or SPICE numbers
(``{"R1": "10u"}``). Errors are the same types as the command line's
(:class:`~netlistdyn.base.errors.NetlistError` with ``file:line``,
:class:`~netlistdyn.base.errors.UsageError`), worded in terms of the
arguments (``params['R9']``), not of command-line flags. The command line
calls :func:`simulation_pipeline` and :func:`validation_pipeline` itself, so
both give the same numbers.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from netlistdyn.analysis.coordinates import prepare
from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.base.errors import UsageError
from netlistdyn.spice.ngspice import ngspice_missing
from netlistdyn.statespace.model import StateSpaceModel
from netlistdyn.workflows.pipelines import (
    NetlistSource,
    Simulation,
    SimulationError,
    Sweep,
    SweepCase,
    Validation,
    api_errors,
    compile_model,
    initial_state,
    load_source,
    output_names,
    read_netlist,
    simulation_pipeline,
    to_number,
    validation_pipeline,
)
from netlistdyn.workflows.sweep import SweepSource, expand_cases, run_sweep

if TYPE_CHECKING:  # the module imports sympy, an optional extra loaded only by symbolic()
    from netlistdyn.formulation.symbolic import SymbolicModel

# --- compile -----------------------------------------------------------------------


# --- simulate ------------------------------------------------------------------------


def simulate(
    netlist: NetlistSource,
    params: Mapping[str, Any] | None = None,
    outputs: str | Sequence[str] | None = None,
    *,
    tstop: float | str | None = None,
    tstep: float | str | None = None,
    method: str = "auto",
    rtol: float | str = 1e-10,
    atol: float | str | None = None,
    x0: Mapping[str, Any] | Sequence[float] | None = None,
    force: bool = False,
    step: float | str | None = None,
) -> Simulation:
    """Time response of a netlist to its own source waveforms, from where SPICE starts it (or ``x0``).

    Parameters
    ----------
    netlist : str, path-like or file object
        Path, netlist text or file object (see :func:`read_netlist`).
    params : mapping, optional
        ``.param`` overrides; numbers or SPICE numbers (``{"R1": "10u"}``).
    outputs : str or sequence of str, optional
        ``v(node)``, ``v(a,b)``, ``i(element)`` ...; default every node voltage.
    tstop, tstep : float or str, optional
        Horizon and output step (s); SPICE numbers accepted (``"20m"``).
    method : str
        ``auto``, ``exact``, ``rational``, ``krylov``, ``euler`` (fixed ``step``) or a
        ``solve_ivp`` method.
    rtol, atol : float or str
        Tolerances.
    x0 : mapping or sequence, optional
        Initial state as a vector, or by name as ``--ic`` takes it: state names
        (``{"q(C1)": 1e-6}``) and physical variables (``{"angle(r1)": -0.01}``,
        ``x(node)``, ``v(node)``, ``omega(rod)``...), mixed; states no condition
        involves start at 0.
    force : bool
        Run an explicit method on a stiff model anyway.
    step : float or str, optional
        The fixed step of ``method="euler"`` (s); the output times are its steps,
        and the result's ``stats``/``message`` give its error against the exact
        solution at those times.

    Returns
    -------
    Simulation

    Raises
    ------
    SimulationError
        When the method refused, failed or diverged.
    """
    outputs = output_names(outputs)
    with api_errors(params):
        if isinstance(x0, Mapping) and x0:
            parsed = read_netlist(netlist, params)
            conditions = [
                f"{name}={value if isinstance(value, str) else repr(float(value))}"
                for name, value in x0.items()
            ]
            prepared = prepare(parsed, list(outputs) if outputs else None, None, conditions)
            model, start, shown = prepared.full, prepared.x0, prepared.shown
        else:
            parsed, model = compile_model(netlist, params, outputs)
            start, shown = initial_state(model, x0), tuple(model.outputs)
        result = simulation_pipeline(
            parsed,
            model,
            None if tstop is None else to_number(tstop, "tstop"),
            None if tstep is None else to_number(tstep, "tstep"),
            method,
            to_number(rtol, "rtol"),
            None if atol is None else to_number(atol, "atol"),
            start,
            force,
            step=None if step is None else to_number(step, "step"),
        )
    if tuple(shown) != result.outputs:  # variables the conditions needed are not outputs
        keep = [result.outputs.index(name) for name in shown]
        result = replace(
            result,
            values=result.values[:, keep],
            outputs=tuple(shown),
            units=tuple(result.units[k] for k in keep),
        )
    if not result.ok and result.status != "unverified":  # unverified: numbers, with the reason
        raise SimulationError(f"{result.method} {result.status}: {result.message}", result)
    return result


# --- validate -------------------------------------------------------------------------


def validate(
    netlist: NetlistSource,
    params: Mapping[str, Any] | None = None,
    outputs: str | Sequence[str] | None = None,
    *,
    model_params: Mapping[str, Any] | None = None,
    tstop: float | str | None = None,
    tstep: float | str | None = None,
    rtol: float | str = 1e-3,
    timeout: float | str = 600.0,
    pz: bool = True,
    ngspice_reltol: float | str | None = None,
    ngspice_maxstep: float | str | None = None,
) -> Validation:
    """Run the netlist through ngspice and through the compiled model and compare the responses.

    Parameters
    ----------
    netlist, params, outputs
        As :func:`simulate`.
    model_params : mapping, optional
        ``.param`` overrides applied to the model only (ngspice keeps the
        netlist's values).
    tstop, tstep : float or str, optional
        Horizon and output step (s).
    rtol : float or str
        Pass threshold: max error relative to each waveform's peak.
    timeout : float or str
        Seconds allowed to ngspice.
    pz : bool
        Compare ngspice's ``.pz`` poles (models up to 6 states).
    ngspice_reltol, ngspice_maxstep : float or str, optional
        ngspice's reference settings (default: chosen from the eigenvalues).

    Returns
    -------
    Validation

    Raises
    ------
    RuntimeError
        When ngspice is not installed.
    """
    outputs = output_names(outputs)

    missing = ngspice_missing()
    if missing:
        raise RuntimeError(missing)
    with api_errors(params, model_params):
        return validation_pipeline(
            netlist,
            params,
            outputs,
            model_params,
            None if tstop is None else to_number(tstop, "tstop"),
            None if tstep is None else to_number(tstep, "tstep"),
            to_number(rtol, "rtol"),
            to_number(timeout, "timeout"),
            pz,
            {
                "reltol": None if ngspice_reltol is None else to_number(ngspice_reltol, "ngspice_reltol"),
                "maxstep": None if ngspice_maxstep is None else to_number(ngspice_maxstep, "ngspice_maxstep"),
            },
        )


# --- sweep --------------------------------------------------------------------------------


def sweep(
    netlist: NetlistSource,
    params: Mapping[str, Any],
    outputs: str | Sequence[str] | None = None,
    *,
    jobs: int = 1,
    eig: str = "auto",
) -> Sweep:
    """Eigenvalues and stability for each case of a parameter sweep (the tree is found once).

    Parameters
    ----------
    netlist : str, path-like or file object
        Path, netlist text or file object.
    params : mapping
        Per parameter, its values: a sequence of numbers or SPICE numbers, or
        a string as on the command line (``"1m,100"``, ``"log:1u:1m:4"``).
        Sequences of equal length vary together; otherwise every combination runs.
    outputs : str or sequence of str, optional
        Output specifications.
    jobs : int
        Worker processes.
    eig : {"auto", "all", "extreme"}
        Which eigenvalues each case computes.

    Returns
    -------
    Sweep
    """
    outputs = output_names(outputs)

    if eig not in ("auto", "all", "extreme"):
        raise UsageError(f"eig: {eig!r}; choose auto, all or extreme")
    with api_errors(params):
        loaded = load_source(netlist)
        source = (
            SweepSource.read(loaded.name) if loaded.text is None else SweepSource(loaded.name, loaded.text)
        )
        title = source.text.splitlines()[0] if source.text else ""
        records = run_sweep(source, expand_cases(params), list(outputs) if outputs else None, jobs, eig=eig)
    cases = tuple(
        SweepCase(r["params"], error=r["error"])
        if "error" in r
        else SweepCase(
            r["params"],
            tuple(complex(re, im) for re, im in r["eigenvalues"]),
            r["stability"],
            r["stiffness_ratio"],
        )
        for r in records
    )
    return Sweep(title, cases)


def eigenvalues(model: StateSpaceModel, which: str = "auto") -> Any:
    """The :class:`~netlistdyn.analysis.eigen.EigenAnalysis` of a model (``which`` as ``analyze --eig``)."""
    if which not in ("auto", "all", "extreme"):
        raise UsageError(f"which: {which!r}; choose auto, all or extreme")
    return analyze_eigenvalues(model.A_sparse, which, pencil=model.pencil)


__all__ = [
    "NetlistSource",
    "Simulation",
    "SimulationError",
    "Sweep",
    "SweepCase",
    "Validation",
    "simulate",
    "sweep",
    "validate",
]


def compile(
    netlist: NetlistSource,
    params: Mapping[str, Any] | None = None,
    outputs: str | Sequence[str] | None = None,
    coordinates: Sequence[str] | str | None = None,
) -> StateSpaceModel:
    """Parse and compile a netlist.

    Parameters
    ----------
    netlist : str, path-like or file object
        A path, netlist text (a string with a line break; its first line is
        the title) or an open file such as ``io.StringIO``.
    params : mapping, optional
        ``.param`` overrides: numbers or SPICE numbers (``{"R1": "10u"}``).
    outputs : str or sequence of str, optional
        Output specifications (default: every node voltage).
    coordinates : sequence of str or str, optional
        Present the model in these variables (``["x(b1)", "v(b1)", ...]``):
        states named by them, outputs the coordinates unless ``outputs`` is
        given. ``netlistdyn.analysis.coordinates.prepare`` also gives T and cond(T).

    Returns
    -------
    StateSpaceModel
    """
    outputs = output_names(outputs)

    if coordinates is not None:
        with api_errors(params):
            return prepare(read_netlist(netlist, params), outputs, coordinates).model
    return compile_model(netlist, params, outputs)[1]


def symbolic(
    netlist: NetlistSource,
    params: Mapping[str, Any] | None = None,
    outputs: str | Sequence[str] | None = None,
    keep: Sequence[str] | None = None,
) -> SymbolicModel:
    """Parse a netlist and compile it with element values as sympy symbols (needs sympy).

    Parameters
    ----------
    netlist : str, path-like or file object
        As :func:`compile`.
    params : mapping, optional
        ``.param`` overrides (they set the values of elements not in ``keep``).
    outputs : str or sequence of str, optional
        Output specifications.
    keep : sequence of str, optional
        Element names to keep symbolic; default all.

    Returns
    -------
    SymbolicModel
        ``.A .B .C .D .D1`` as ``sympy.ImmutableMatrix``, the labels, and
        ``.numeric(values)`` to evaluate them.
    """
    outputs = output_names(outputs)
    from netlistdyn.formulation.symbolic import symbolic_model  # noqa: PLC0415 (deferred, imports sympy: optional symbolic extra)

    with api_errors(params):
        return symbolic_model(read_netlist(netlist, params), outputs, keep)
