"""Command line: thin wrappers over the pipeline stages.

Exit codes: 0 success, 1 bad netlist, 2 bad command line, 3 validation
mismatch, 70 internal error. Errors are one line on stderr, never a
traceback (set ``NETLISTDYN_DEBUG=1`` to see one).
"""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from .errors import NetlistError, UsageError
from .values import parse_number

EXIT_NETLIST = 1
EXIT_USAGE = 2
EXIT_MISMATCH = 3
EXIT_NO_NGSPICE = 4
EXIT_INTERNAL = 70


def parse_param_overrides(items: tuple[str, ...]) -> dict[str, float]:
    """``("R1=1k", ...)`` → ``{"r1": 1000.0}``; SPICE numbers accepted."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        value = parse_number(text.strip()) if sep else None
        if not name.strip() or value is None:
            raise UsageError(f"--param {item!r}: expected NAME=VALUE with a number (e.g. R1=1k)")
        out[name.strip().lower()] = value
    return out


def write_atomic(path: str, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(dir=target.parent or Path("."), prefix=f".{target.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(text)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def emit(text: str, out: str | None) -> None:
    """Send a finished document to ``out`` (atomically) or stdout."""
    if out:
        write_atomic(out, text)
    else:
        sys.stdout.write(text)


def run_guarded(action: Callable[[], int | None]) -> None:
    """Run a command body, turning errors into one-line messages and exit codes."""
    try:
        code = action() or 0
    except NetlistError as exc:
        click.echo(str(exc), err=True)
        sys.exit(EXIT_NETLIST)
    except UsageError as exc:
        click.echo(f"netlistdyn: error: {exc}", err=True)
        sys.exit(EXIT_USAGE)
    except OSError as exc:
        click.echo(f"netlistdyn: error: {exc.filename or ''}: {exc.strerror or exc}", err=True)
        sys.exit(EXIT_USAGE)
    except Exception as exc:
        if os.environ.get("NETLISTDYN_DEBUG"):
            raise
        click.echo(f"netlistdyn: internal error: {type(exc).__name__}: {exc} (please report)", err=True)
        sys.exit(EXIT_INTERNAL)
    sys.exit(code)


def _print_warnings(warnings: Any) -> None:
    for warning in warnings:
        click.echo(str(warning), err=True)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="netlistdyn")
def main() -> None:
    """Compile SPICE-like netlists to state-space models, analyse and validate them."""


output_option = click.option(
    "--output",
    "outputs",
    multiple=True,
    metavar="SPEC",
    help="Output: v(node), v(a,b) or i(element). Repeatable. Default: every node voltage.",
)
param_option = click.option(
    "--param",
    "params",
    multiple=True,
    metavar="NAME=VALUE",
    help="Override a .param for this run. Repeatable.",
)
format_option = click.option(
    "--format",
    "fmt",
    type=click.Choice(["text", "json"]),
    default="text",
    show_default=True,
)
out_option = click.option(
    "-o",
    "--out",
    type=click.Path(dir_okay=False, writable=True),
    default=None,
    help="Write the report to this file (atomically) instead of stdout.",
)


@main.command()
@click.argument("netlist", type=click.Path(exists=True, dir_okay=False))
@output_option
@param_option
@format_option
@click.option(
    "--eig",
    type=click.Choice(["auto", "all", "extreme", "none"]),
    default="auto",
    show_default=True,
    help="Eigenvalues: all (dense), extreme (sparse, large models), auto by size, or none.",
)
@out_option
def analyze(
    netlist: str, outputs: tuple[str, ...], params: tuple[str, ...], fmt: str, eig: str, out: str | None
) -> None:
    """Compile NETLIST to x' = Ax + Bu, y = Cx + Du and analyse its eigenvalues."""
    from .analysis import analyze_eigenvalues
    from .formulate import compile_netlist
    from .parser import parse_file
    from .report import model_dict, text_report, to_json

    def body() -> int:
        parsed = parse_file(netlist, parse_param_overrides(params))
        model = compile_netlist(parsed, list(outputs) or None)
        _print_warnings(model.info.warnings)
        analysis = None if eig == "none" else analyze_eigenvalues(model.A_sparse, eig)
        if fmt == "json":
            doc = model_dict(model, analysis)
            doc["netlist"] = netlist
            emit(to_json(doc), out)
        else:
            emit(text_report(model, analysis, netlist), out)
        return 0

    run_guarded(body)


@main.command()
@click.argument("netlist", type=click.Path(exists=True, dir_okay=False))
@output_option
@param_option
@click.option(
    "--model-param",
    "model_params",
    multiple=True,
    metavar="NAME=VALUE",
    help="Override a .param in the compiled model only (ngspice keeps the netlist's value): "
    "shows what size of modelling error validate detects.",
)
@click.option(
    "--tstop", type=float, default=None, help="Horizon [s] (default: .tran, else from eigenvalues)."
)
@click.option("--tstep", type=float, default=None, help="Output step [s].")
@click.option(
    "--rtol",
    type=float,
    default=1e-3,
    show_default=True,
    help="Pass threshold: max error relative to each waveform's peak.",
)
@click.option("--timeout", type=float, default=600.0, show_default=True, help="Seconds allowed to ngspice.")
@click.option(
    "--plot", type=click.Path(dir_okay=False), default=None, help="Write a PNG overlay of both responses."
)
@click.option(
    "--pz/--no-pz",
    default=True,
    show_default=True,
    help="Compare ngspice's .pz poles for models of up to 6 states (informative).",
)
@format_option
@out_option
def validate(
    netlist: str,
    outputs: tuple[str, ...],
    params: tuple[str, ...],
    model_params: tuple[str, ...],
    tstop: float | None,
    tstep: float | None,
    rtol: float,
    timeout: float,
    plot: str | None,
    pz: bool,
    fmt: str,
    out: str | None,
) -> None:
    """Run NETLIST through ngspice and the compiled model and compare the responses.

    Exit status 0 when every output agrees within --rtol of its peak, 3 when not.
    """
    from .spice import ngspice_missing

    def body() -> int:
        missing = ngspice_missing()
        if missing:
            click.echo(f"netlistdyn: {missing}", err=True)
            return EXIT_NO_NGSPICE
        from .analysis import analyze_eigenvalues
        from .formulate import compile_netlist
        from .parser import parse_file
        from .probes import default_probes, parse_probe
        from .report import to_json, validation_dict, validation_text
        from .validate import choose_horizon, compare, compare_poles, spice_settings_for

        overrides = parse_param_overrides(params)
        parsed = parse_file(netlist, overrides)
        probes = [parse_probe(o, parsed) for o in outputs] if outputs else default_probes(parsed)
        model_net = parse_file(netlist, {**overrides, **parse_param_overrides(model_params)})
        model = compile_netlist(model_net, [p.name for p in probes])
        _print_warnings(model.info.warnings)
        if (tstop is not None and tstop <= 0) or (tstep is not None and tstep <= 0):
            raise UsageError("--tstop and --tstep must be positive")
        eig = analyze_eigenvalues(model.A_sparse)
        horizon = choose_horizon(parsed, eig, tstop, tstep)
        settings = spice_settings_for(horizon, eig)
        report = compare(parsed, model, probes, horizon, settings, rtol, timeout)
        if pz:
            from dataclasses import replace

            report = replace(report, poles=compare_poles(parsed, eig, probes))
        if plot and report.spice.ok:
            from .plots import validation_plot

            validation_plot(report, plot)
        if fmt == "json":
            emit(to_json(validation_dict(report, parsed.title)), out)
        else:
            emit(validation_text(report, parsed.title), out)
        return 0 if report.passed else EXIT_MISMATCH

    run_guarded(body)


if __name__ == "__main__":  # pragma: no cover
    main()
