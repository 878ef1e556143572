"""The command line's pipelines, shared with the Python API: read a netlist, compile, simulate, validate,
sweep, each returning a typed result.

The command line (:mod:`netlistdyn.cli`) and the API (:mod:`netlistdyn.api`) both call
:func:`simulation_pipeline` and :func:`validation_pipeline`, so both give the same numbers."""

from __future__ import annotations

import math
import os
import re
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from netlistdyn.analysis.eigen import analyze_eigenvalues
from netlistdyn.base.errors import UsageError
from netlistdyn.base.values import parse_number
from netlistdyn.circuit.netlist import Netlist
from netlistdyn.circuit.probes import default_probes, parse_probes
from netlistdyn.devices.units import signal_units
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_file, parse_text
from netlistdyn.io.display import simulation_html, simulation_text
from netlistdyn.io.report import sweep_text, validation_text
from netlistdyn.simulation import integrators
from netlistdyn.simulation.foh import Horizon, choose_horizon, input_signals
from netlistdyn.simulation.initial import around_equilibrium, transient_start
from netlistdyn.simulation.nltransient import simulate_nonlinear
from netlistdyn.simulation.planartransient import simulate_planar
from netlistdyn.simulation.sampling import output_grid
from netlistdyn.spice.validate import compare, compare_poles, spice_settings_for, with_original_check
from netlistdyn.statespace.model import StateSpaceModel

#: A netlist as the API accepts it: a path, netlist text, or a file object.
NetlistSource = str | os.PathLike[str] | IO[str]


class SimulationError(RuntimeError):
    """The integration method refused, failed or diverged (the message says why).

    Attributes
    ----------
    result : Simulation
        What the method returned, with its ``status`` and ``message``.
    """

    def __init__(self, message: str, result: Simulation) -> None:
        super().__init__(message)
        self.result = result


def to_number(value: Any, what: str) -> float:
    """A float from a number or a SPICE number string (``"10u"``, ``"1meg"``).

    Raises
    ------
    UsageError
        Naming ``what`` when ``value`` is neither.
    """
    if isinstance(value, str):
        parsed = parse_number(value.strip())
        if parsed is None:
            raise UsageError(f"{what}: {value!r} is not a number (SPICE numbers such as '10u' are accepted)")
        return parsed
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise UsageError(f"{what}: expected a number or a SPICE number string, got {type(value).__name__}")
    return float(value)


def to_numbers(params: Mapping[str, Any] | None, what: str = "params") -> dict[str, float]:
    """``{"R1": "10u"}`` → ``{"R1": 1e-05}`` (names keep their spelling)."""
    return {str(k): to_number(v, f"{what}[{k!r}]") for k, v in (params or {}).items()}


@dataclass(frozen=True)
class NetlistText:
    """A netlist's text and the name its messages use (``text`` None: read ``name`` from disk)."""

    name: str
    text: str | None = None

    def parse(self, params: Mapping[str, Any] | None = None) -> Netlist:
        """The netlist with ``params`` (numbers or SPICE numbers) applied."""
        overrides = to_numbers(params)
        if self.text is None:
            return parse_file(self.name, overrides)
        return parse_text(self.text, self.name, overrides)


def load_source(source: NetlistSource | NetlistText) -> NetlistText:
    """Tell a path from netlist text and read a file object to its end.

    A ``str`` with a line break is netlist text (its first line is the
    title); any other ``str`` or path-like is a file name; an object with
    ``read()`` is read (its ``name``, if any, is used in messages and for
    ``.include``).
    """
    if isinstance(source, NetlistText):
        return source
    if hasattr(source, "read"):
        text = source.read()
        if isinstance(text, bytes):
            text = text.decode()
        name = getattr(source, "name", None)
        return NetlistText(name if isinstance(name, str) else "<stream>", text)
    if isinstance(source, str) and ("\n" in source or "\r" in source):
        return NetlistText("<string>", source)
    if isinstance(source, str | os.PathLike):
        return NetlistText(os.fspath(source))
    raise UsageError(f"netlist: expected a path, netlist text or a file object, got {type(source).__name__}")


def read_netlist(source: NetlistSource | NetlistText, params: Mapping[str, Any] | None = None) -> Netlist:
    """Parse a netlist given as a path, as text or as a file object (see :func:`load_source`).

    Parameters
    ----------
    source : str, path-like or file object
    params : mapping, optional
        ``.param`` overrides, numbers or SPICE number strings.

    Returns
    -------
    Netlist
    """
    return load_source(source).parse(params)


#: Command-line flags and the API argument each stands for.
_ARGUMENTS = {
    "param": "params",
    "output": "outputs",
    "symbols": "keep",
    "model-param": "model_params",
    "ic": "x0",
}


def argument_message(message: str, spelling: Mapping[str, str] | None = None) -> str:
    """Reword a command-line message for the API: ``--param r9: ...`` → ``params['R9']: ...``.

    Parameters
    ----------
    message : str
        The message as the command line words it.
    spelling : mapping, optional
        Lower-case parameter name → the caller's spelling.
    """
    spelling = spelling or {}

    def param(match: re.Match[str]) -> str:
        name = match.group(2)
        return f"{_ARGUMENTS[match.group(1)]}[{spelling.get(name.lower(), name)!r}]"

    message = re.sub(r"--(param|model-param) ([A-Za-z_][\w.]*)(?=[:=])", param, message)
    return re.sub(r"--([a-z][a-z0-9-]*)", lambda m: _ARGUMENTS.get(m[1], m[1].replace("-", "_")), message)


@contextmanager
def api_errors(*params: Mapping[str, Any] | None) -> Iterator[None]:
    """Re-raise :class:`UsageError` with the message in terms of the API's arguments."""
    spelling = {str(k).lower(): str(k) for p in params for k in (p or {})}
    try:
        yield
    except UsageError as exc:
        raise UsageError(argument_message(str(exc), spelling)) from None


def output_names(outputs: str | Sequence[str] | None) -> list[str] | None:
    """The API's ``outputs`` as a list: one string is one output (``"v(a,b)"`` is one voltage).

    Parameters
    ----------
    outputs : str, sequence of str or None
        Output specifications.

    Returns
    -------
    list of str or None
        ``None`` (the default outputs) when ``outputs`` is ``None`` or empty.
    """
    if outputs is None:
        return None
    names = [outputs] if isinstance(outputs, str) else list(outputs)
    return names or None


def compile_model(
    source: NetlistSource, params: Mapping[str, Any] | None = None, outputs: str | Sequence[str] | None = None
) -> tuple[Netlist, StateSpaceModel]:
    """Parse and compile; (netlist, model). See :func:`netlistdyn.compile`."""
    with api_errors(params):
        netlist = read_netlist(source, params)
        return netlist, compile_netlist(netlist, output_names(outputs))


@dataclass(frozen=True, eq=False)
class Simulation:
    """A simulated response.

    Attributes
    ----------
    title : str
        Netlist title.
    time : numpy.ndarray
        Output times (s).
    values : numpy.ndarray
        ``(len(time), len(outputs))`` samples, column j for ``outputs[j]``.
    outputs : tuple of str
        Output names, as in :attr:`StateSpaceModel.outputs`.
    units : tuple of str
        Unit of each output (V, A, m/s, N ...; empty when unknown).
    method, setting : str
        Integration method and its accuracy setting.
    seconds : float
        Wall time of the integration (s).
    status, message : str
        ``ok``, or why the method refused, failed or diverged.
    horizon : Horizon
        Stop time, output step (s) and where they came from.
    stats : dict
        Method-specific counts.
    eigen : EigenAnalysis or None
        The eigenvalues that chose the horizon or sized the growth warnings; None when neither
        needed them (a ``.tran`` or ``tstop`` and a passive model).
    start : str
        Where the transient started (:func:`netlistdyn.simulation.initial.transient_start`): the DC
        operating point, the ``UIC`` initial conditions, or the given initial state.
    warnings : tuple of str
        What the run found worth saying (``file:line: warning: ...``): an output grid refined or
        too coarse for a mode or a pulse, an initial condition that does not apply.
    """

    title: str
    time: NDArray[np.float64]
    values: NDArray[np.float64]
    outputs: tuple[str, ...]
    units: tuple[str, ...]
    method: str
    setting: str
    seconds: float
    status: str
    message: str
    horizon: Horizon
    stats: Mapping[str, float] = field(default_factory=dict)
    eigen: Any = field(default=None, repr=False)
    start: str = ""
    warnings: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """True when the method produced a trustworthy answer."""
        return self.status == "ok"

    def __getitem__(self, name: str) -> NDArray[np.float64]:
        """The samples of one output, by name (``sim["v(a)"]``)."""
        try:
            return self.values[:, self.outputs.index(name)]
        except ValueError:
            raise KeyError(f"{name!r}: outputs are {', '.join(self.outputs)}") from None

    def __repr__(self) -> str:
        return simulation_text(self)

    def _repr_html_(self) -> str:
        return simulation_html(self)


def check_horizon(horizon: Horizon) -> None:
    """Refuse a non-positive horizon or an output step longer than the horizon."""
    if not (horizon.tstop > 0 and math.isfinite(horizon.tstop)):
        raise UsageError(f"--tstop {horizon.tstop:g}: must be positive")
    if not (horizon.tstep > 0 and math.isfinite(horizon.tstep)):
        raise UsageError(f"--tstep {horizon.tstep:g}: must be positive")
    if horizon.tstep > horizon.tstop:
        raise UsageError(
            f"--tstep {horizon.tstep:g} is longer than the horizon --tstop {horizon.tstop:g} "
            f"({horizon.source}): there would be a single sample"
        )


#: Most output samples one simulation returns.
MAX_POINTS = 10_000_000


def initial_state(model: StateSpaceModel, x0: Mapping[str, Any] | Sequence[float] | None) -> Any:
    """The initial state from ``{"q(C1)": "1u"}`` (names as in ``model.states``) or a vector."""
    if x0 is None:
        return None
    if not isinstance(x0, Mapping):
        vector = np.asarray(x0, dtype=float)
        if vector.shape != (model.nstates,):
            raise UsageError(f"--ic: expected {model.nstates} values, got shape {vector.shape}")
        return vector
    state = np.zeros(model.nstates)
    index = {name.lower(): k for k, name in enumerate(model.states)}
    for name, value in x0.items():
        key = str(name).strip().lower()
        if key not in index:
            raise UsageError(f"--ic {name}: no state {name!r}; the states are {', '.join(model.states)}")
        state[index[key]] = to_number(value, f"--ic {name}")
    return state


def simulation_pipeline(
    netlist: Netlist,
    model: StateSpaceModel,
    tstop: float | None = None,
    tstep: float | None = None,
    method: str = "auto",
    rtol: float = 1e-10,
    atol: float | None = None,
    x0: Any = None,
    force: bool = False,
    progress: Callable[[float], None] | None = None,
    warn: Callable[[Any], None] | None = None,
    step: float | None = None,
) -> Simulation:
    """Horizon, input signals and integration: what ``simulate`` runs.

    Parameters
    ----------
    netlist, model
        The parsed netlist (for its sources and ``.tran``) and its model.
    tstop, tstep : float, optional
        Horizon and output step (s); default the ``.tran``, else from the
        eigenvalues.
    method, rtol, atol, force
        As :func:`netlistdyn.simulation.integrators.run`.
    x0 : array, optional
        Initial state (see :func:`initial_state`); by default where SPICE starts the
        transient: the DC operating point, or with ``.tran ... UIC`` the netlist's initial
        conditions (:func:`netlistdyn.simulation.initial.transient_start`).
    progress : callable, optional
        Called with the fraction done.
    step : float, optional
        The fixed step of ``method="euler"`` (s); its output times are the steps.
    """

    for value, name in ((tstop, "--tstop"), (tstep, "--tstep"), (step, "--step")):
        if value is not None and not value > 0:
            raise UsageError(f"{name} must be positive")
    if method == "euler":
        if step is None:
            raise UsageError("--method euler needs a fixed step: --step H (s)")
        if tstep is not None and abs(tstep - step) > 1e-9 * step:
            raise UsageError(
                f"--method euler reports every step: --tstep must be --step ({step:g}) or omitted"
            )
        tstep = step
    elif step is not None:
        raise UsageError("--step is the fixed step of --method euler")
    # The eigenvalues here place the horizon and size the growth warnings: A's own error
    # estimates serve, and the check on the circuit equations (extended precision; 15 CPU s of a
    # 0.2 s run on a 100-section ladder) is left to analyze, which reports the error bars. They
    # are computed only when needed (ARPACK took 4 of the 9 CPU s of a 1000-section ladder): for a
    # horizon that neither the arguments nor a .tran give, or a model not known to be passive.
    needed = (tstop is None and netlist.tran is None) or not model.info.passive
    eig = (
        analyze_eigenvalues(model.A_sparse, "auto" if model.nstates <= 1000 else "extreme")
        if needed
        else None
    )
    said: list[Any] = []

    def say(note: Any) -> None:
        said.append(note)
        if warn is not None:
            warn(note)

    horizon = choose_horizon(netlist, eig, tstop, tstep)
    check_horizon(horizon)
    count = round(horizon.tstop / horizon.tstep)
    if count > MAX_POINTS:
        raise UsageError(f"{count} output points: choose a larger --tstep")
    # the sources' TSTEP-based defaults (a PULSE's TR, TF) follow .tran's step, not the output grid's;
    # resolving them first also refuses a source with too many corners before any are listed
    signals = input_signals(netlist, horizon.tstep, horizon.tstop)
    if method == "euler":  # the output times are the steps k·h up to tstop
        times = np.arange(int(horizon.tstop / horizon.tstep * (1 + 1e-12)) + 1, dtype=float) * horizon.tstep
        shown = horizon
    else:  # a grid that shows the fastest visible mode and every source corner (see sampling)
        from_tran = tstop is None and tstep is None and netlist.tran is not None  # not the user's grid
        grid = output_grid(netlist, model, horizon.tstep, horizon.tstop, from_tran, MAX_POINTS)
        times = grid.times
        shown = horizon if grid.step >= horizon.tstep else replace(horizon, tstep=grid.step)
        for note in grid.warnings:
            say(note)
    level = None
    how = "the given initial state"
    if netlist.planar:  # a planar mechanism: its exact equations of motion
        result, how = simulate_planar(netlist, model.outputs, times, method, rtol, x0, progress, step)
    elif netlist.is_nonlinear:  # the model is the linearisation: integrate the circuit itself
        u0 = signals(np.array([0.0]))[0]
        result, how = simulate_nonlinear(
            netlist, model.outputs, times, method, rtol, x0, progress, model.states, u0
        )
    else:
        if x0 is None:
            start = transient_start(netlist, model, signals(np.array([0.0]))[0])
            x0, how = start.x0, start.how
            for warning in start.warnings:
                say(warning)
            shifted = None if start.uic else around_equilibrium(model, signals, x0)
            if shifted is not None:  # from the operating point: its constant plus what moves
                signals, level = shifted
                x0 = None
        result = integrators.run(model, signals, times, method, rtol, atol, x0, force, progress, step)
        if level is not None:
            result = replace(result, outputs=result.outputs + level[None, :])
    return Simulation(
        title=netlist.title,
        time=result.time,
        values=result.outputs,
        outputs=tuple(model.outputs),
        units=signal_units(netlist, model.outputs),
        method=result.method,
        setting=result.setting,
        seconds=result.seconds,
        status=result.status,
        message=result.message,
        horizon=shown,
        stats=dict(result.stats),
        eigen=eig,
        start=how,
        warnings=tuple(str(w) for w in said),
    )


@dataclass(frozen=True, eq=False)
class Validation:
    """The compiled model against ngspice.

    Attributes
    ----------
    title : str
        Netlist title.
    passed : bool
        ngspice ran and every output is within ``rtol`` of its peak.
    outputs : tuple of str
        Output names compared.
    report : ValidationReport
        Everything ``validate`` found: per-output errors
        (``report.comparisons``), ngspice's settings and run, both
        waveforms (``report.time``, ``report.ours``).
    reference_accuracy : float
        Bound on ngspice's accumulated trapezoidal phase error relative to
        the amplitude of each oscillating mode (:func:`reference_accuracy`);
        0 when no mode oscillates (ngspice's reltol sets the accuracy).
    """

    title: str
    passed: bool
    outputs: tuple[str, ...]
    report: Any
    reference_accuracy: float = 0.0

    def __repr__(self) -> str:
        return validation_text(self.report, self.title).rstrip("\n")


def validation_pipeline(
    source: NetlistSource | NetlistText,
    params: Mapping[str, Any] | None = None,
    outputs: Sequence[str] | None = None,
    model_params: Mapping[str, Any] | None = None,
    tstop: float | None = None,
    tstep: float | None = None,
    rtol: float = 1e-3,
    timeout: float = 600.0,
    pz: bool = True,
    reference: Mapping[str, float | None] | None = None,
    warn: Callable[[Any], None] | None = None,
) -> Validation:
    """What ``validate`` runs: ngspice and the model on the same netlist, compared.

    Parameters
    ----------
    reference : mapping, optional
        ngspice settings chosen by the user (``reltol``, ``maxstep``); None
        values keep the defaults.
    warn : callable, optional
        Receives each compile warning.
    """

    loaded = load_source(source)
    parsed = loaded.parse(params)
    probes = parse_probes(outputs, parsed) if outputs else default_probes(parsed)
    model_net = loaded.parse({**to_numbers(params), **to_numbers(model_params)}) if model_params else parsed
    model = compile_netlist(model_net, [p.name for p in probes])
    for warning in model.info.warnings:
        if warn is not None:
            warn(warning)
    if (tstop is not None and tstop <= 0) or (tstep is not None and tstep <= 0):
        raise UsageError("--tstop and --tstep must be positive")
    eig = analyze_eigenvalues(model.A_sparse, pencil=model.pencil)
    horizon = choose_horizon(parsed, eig, tstop, tstep)
    check_horizon(horizon)
    settings = spice_settings_for(horizon, eig, model.nstates)
    chosen = {k: v for k, v in (reference or {}).items() if v is not None}
    if chosen:
        settings = reference_settings(settings, chosen)
    report = compare(parsed, model, probes, horizon, settings, rtol, timeout)
    report = _original_check(report, loaded, parsed, model, probes, eig, params, timeout)
    if pz:
        report = replace(report, poles=compare_poles(parsed, eig, probes))
    bound = reference_accuracy(report.spice.settings, eig, horizon.tstop)
    if bound > 0:
        note = (
            f"reference accuracy: ngspice's trapezoidal phase error at its maximum step is bounded by "
            f"{bound:.1g} of each oscillating mode's amplitude over the horizon"
        )
        if bound > rtol:
            note += f", more than rtol {rtol:g}: lower --ngspice-maxstep for a tighter reference"
        report = replace(report, notes=(*report.notes, note))
    return Validation(parsed.title, report.passed, tuple(c.name for c in report.comparisons), report, bound)


def reference_accuracy(settings: Any, eig: Any, tstop: float) -> float:
    """Bound on the trapezoidal rule's accumulated phase/growth error at ngspice's maximum step.

    (|λ|h)²·|λ|T/12 for every oscillatory or growing mode over the time T it
    lasts (five time constants, at most the horizon), with h the maximum step
    (ngspice's own default tstop/50 when none is set); 0 when no mode
    accumulates such an error (reltol then sets the accuracy). Relative to
    each mode's amplitude.
    """
    step = settings.tmax if settings.tmax else tstop / 50
    worst = 0.0
    for mode in eig.modes if eig is not None else ():
        lam = mode.value
        if lam.imag or lam.real > 0:
            span = min(tstop, 5.0 / -lam.real) if lam.real < 0 else tstop
            rate = abs(lam)
            worst = max(worst, (rate * step) ** 2 * rate * span / 12)
    return worst


def _original_check(
    report: Any,
    loaded: NetlistText,
    parsed: Netlist,
    model: StateSpaceModel,
    probes: Any,
    eig: Any,
    params: Mapping[str, Any] | None,
    timeout: float,
) -> Any:
    """ngspice's reading of the original file against the model (text is written to a temporary file)."""
    # ngspice's alterparam matches the lower-case names ngspice gives parameters.
    overrides = {k.lower(): v for k, v in to_numbers(params).items()}
    if loaded.text is None:
        return with_original_check(report, loaded.name, parsed, model, probes, eig, overrides, timeout)
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "netlist.cir")
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(loaded.text)
        return with_original_check(report, path, parsed, model, probes, eig, overrides, timeout)


def reference_settings(settings: Any, chosen: Mapping[str, float]) -> Any:
    """ngspice settings with the user's ``reltol`` and maximum step (``maxstep``, s)."""
    changes: dict[str, Any] = {}
    if "reltol" in chosen:
        changes["reltol"] = chosen["reltol"]
    if "maxstep" in chosen:
        changes["tmax"] = chosen["maxstep"]
        changes["tstep"] = min(settings.tstep, chosen["maxstep"])
    return replace(settings, **changes)


@dataclass(frozen=True)
class SweepCase:
    """One case of a sweep.

    Attributes
    ----------
    params : dict
        The swept values, by the caller's parameter names.
    eigenvalues : tuple of complex
        Eigenvalues (1/s), in an order that follows each mode from case to case.
    stability : str or None
        Verdict, None when the case failed.
    stiffness_ratio : float or None
    error : str or None
        Why the case failed (``file:line: message``).
    """

    params: Mapping[str, float]
    eigenvalues: tuple[complex, ...] = ()
    stability: str | None = None
    stiffness_ratio: float | None = None
    error: str | None = None


@dataclass(frozen=True)
class Sweep:
    """Eigenvalues per case of a parameter sweep.

    Attributes
    ----------
    title : str
        Netlist title.
    cases : tuple of SweepCase
        In case order.
    """

    title: str
    cases: tuple[SweepCase, ...]

    @property
    def eigenvalues(self) -> NDArray[np.complex128]:
        """Eigenvalues (1/s) as a ``(ncases, nmodes)`` array, modes in tracked order.

        A failed case, or one with fewer modes than the others, is padded with NaN.
        """
        width = max((len(c.eigenvalues) for c in self.cases), default=0)
        table = np.full((len(self.cases), width), complex(np.nan, np.nan))
        for row, case in enumerate(self.cases):
            table[row, : len(case.eigenvalues)] = case.eigenvalues
        return table

    def to_records(self) -> list[dict[str, Any]]:
        """One record per case and mode (a failed case: one record with its ``error``).

        Returns
        -------
        list of dict
            The swept parameters by name, then ``case`` (from 1), ``mode`` (from 1), ``real`` and
            ``imag`` (1/s), ``natural_frequency`` (rad/s), ``natural_frequency_hz`` (Hz), ``damping``
            (ζ, NaN for a zero eigenvalue), ``time_constant`` (s, inf when Re λ = 0), ``stability``
            and ``error``.
        """
        records: list[dict[str, Any]] = []
        for number, case in enumerate(self.cases, start=1):
            base = {**case.params, "case": number}
            if case.error is not None:
                records.append({**base, "mode": None, "stability": None, "error": case.error})
                continue
            for mode, z in enumerate(case.eigenvalues, start=1):
                wn = abs(z)
                records.append(
                    {
                        **base,
                        "mode": mode,
                        "real": z.real,
                        "imag": z.imag,
                        "natural_frequency": wn,
                        "natural_frequency_hz": wn / (2 * math.pi),
                        "damping": -z.real / wn if wn > 0 else math.nan,
                        "time_constant": -1 / z.real if z.real != 0 else math.inf,
                        "stability": case.stability,
                        "error": None,
                    }
                )
        return records

    def to_frame(self) -> Any:
        """:meth:`to_records` as a pandas ``DataFrame`` (needs pandas: ``pip install pandas``)."""
        try:
            import pandas  # noqa: PLC0415 (deferred, pandas: optional, only for a data frame)
        except ImportError:
            raise UsageError("Sweep.to_frame needs pandas: pip install pandas (or use to_records)") from None
        return pandas.DataFrame.from_records(self.to_records())

    def __repr__(self) -> str:
        return sweep_text([sweep_record(c) for c in self.cases]).rstrip("\n")


def sweep_record(case: SweepCase) -> dict[str, Any]:
    """A case as the JSON record ``sweep`` writes."""
    if case.error is not None:
        return {"params": dict(case.params), "error": case.error}
    return {
        "params": dict(case.params),
        "eigenvalues": [[z.real, z.imag] for z in case.eigenvalues],
        "stability": case.stability,
        "stiffness_ratio": case.stiffness_ratio,
    }
