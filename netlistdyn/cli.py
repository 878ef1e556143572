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


if __name__ == "__main__":  # pragma: no cover
    main()
