"""What every command of the command line shares: exit statuses, SPICE numbers as option values, the
options themselves, reading the netlist (or standard input), checking and writing outputs, and
turning errors into one line.

:mod:`netlistdyn.cli` holds the commands.
"""

from __future__ import annotations

import math
import os
import re
import sys
from collections.abc import Callable
from typing import Any

import click

from netlistdyn.base.atomic import STDOUT, check_writable, write_text
from netlistdyn.base.caught_warnings import CaughtWarnings
from netlistdyn.base.errors import ControlDimension, NetlistError, SourceLocation, UsageError
from netlistdyn.base.optional import require
from netlistdyn.base.values import parse_number, split_number

#: Suffixes of a saved model that connect reads as a model, not a netlist.
MODEL_SUFFIXES = (".json", ".npz", ".mat")
#: The values of simulate's --method.
METHOD_CHOICES = ("auto", "exact", "rational", "krylov", "RK45", "DOP853", "Radau", "BDF", "LSODA")


#: Exit statuses: netlist error, usage error, mismatch or failed run, ngspice missing, timeout,
#: internal error.
EXIT_NETLIST = 1
EXIT_USAGE = 2
EXIT_MISMATCH = 3
EXIT_NO_NGSPICE = 4
EXIT_TIMEOUT = 5
EXIT_INTERNAL = 70


#: The netlist argument that means standard input, and its name in messages.
STDIN_NAME = "<stdin>"
DASH = "-"


#: Where ``emit`` sends a report that must leave stdout to a CSV (a NUL byte: never a path).
STDERR = "\0stderr"


#: Longest text accepted as a number on the command line (a double needs < 30 characters).
MAX_NUMBER_TEXT = 64


#: Words longer than this are shortened in error messages (a value of thousands of digits).
_LONG_WORD = re.compile(r"\S{121,}")


def shorten(message: str) -> str:
    """One line, with any absurdly long word cut (it would flood the terminal)."""
    one = " ".join(message.split())
    return _LONG_WORD.sub(lambda m: f"{m[0][:40]}…({len(m[0])} characters)", one)


def option_number(text: str, what: str, *, positive: bool = False) -> float:
    """A finite SPICE number from a command-line value, or a :class:`UsageError` naming ``what``."""
    value = parse_number(text.strip()) if len(text) <= MAX_NUMBER_TEXT else None
    if value is None:
        raise UsageError(f"{what}: {text!r} is not a number")
    if not math.isfinite(value):
        raise UsageError(f"{what}: {text!r} is not a finite number")
    if positive and not value > 0:
        raise UsageError(f"{what}: {text!r} must be positive")
    return value


#: Unit words a command-line number may end with (``10ms``, ``1kHz``); anything else after the
#: number and its scale factor is a typo (``1x``, ``1kk``) and refused, where a netlist field would
#: ignore it as ngspice does.
OPTION_UNITS = frozenset({"", "s", "sec", "hz", "v", "a", "f", "h", "ohm", "ohms", "w", "rad"})


class SpiceNumber(click.ParamType):
    """A numeric option that reads SPICE numbers (``20m``, ``1u``, ``1e-3``, ``1meg``), as ``--param`` does.

    Parameters
    ----------
    positive : bool
        Refuse zero and negative values.
    integer : bool
        Require a whole number (``--points 1k`` is 1000).
    """

    name = "number"

    def __init__(self, positive: bool = False, integer: bool = False) -> None:
        self.positive = positive
        self.integer = integer

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if isinstance(value, int | float) and not isinstance(value, bool):
            number = float(value)
        else:
            text = str(value).strip()
            parsed = split_number(text) if len(text) <= MAX_NUMBER_TEXT else None
            if parsed is None or parsed[1].lower() not in OPTION_UNITS:
                self.fail(
                    f"{shorten(text)!r} is not a number (SPICE numbers such as 20m, 1u, 1e-3, 10ms are "
                    "accepted: a number, a scale factor, and at most a unit)"
                )
            number = parsed[0]
        if not math.isfinite(number):
            self.fail(f"{shorten(str(value))!r} is not a finite number")
        if self.positive and number <= 0:
            self.fail(f"{value!r}: must be positive")
        if self.integer:
            if number != int(number):
                self.fail(f"{value!r}: must be a whole number")
            return int(number)
        return number


#: Shared option types: any SPICE number, a positive one, a positive whole number.
NUMBER = SpiceNumber()
POSITIVE = SpiceNumber(positive=True)
COUNT = SpiceNumber(positive=True, integer=True)


def parse_param_overrides(items: tuple[str, ...], option: str = "--param") -> dict[str, float]:
    """``("R1=1k", ...)`` → ``{"R1": 1000.0}``; SPICE numbers, finite only, names as the user wrote them."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not name.strip() or not sep:
            raise UsageError(f"{option} {shorten(item)!r}: expected NAME=VALUE with a number (e.g. R1=1k)")
        out[name.strip()] = option_number(text, f"{option} {name.strip()}")
    return out


def check_outputs(inputs: tuple[str, ...] = (), **paths: str | None) -> None:
    """Refuse, before any work, output paths that cannot be written, that repeat, or that are inputs.

    ``inputs`` are the netlists and saved models the command reads (``-``: standard input); a
    netlist's ``.include`` and ``.lib`` files count too. An output is refused when it is the same
    file as any of them (symbolic and hard links resolved), so a report never replaces its netlist.
    Keyword names are the options (``out`` for ``-o``, underscores for dashes).
    """
    seen: dict[str, str] = {}
    given: list[tuple[str, str]] = []
    for key, path in paths.items():
        if not path:
            continue
        option = "-o" if key == "out" else "--" + key.replace("_", "-")
        problem = check_writable(path, option)
        if problem:
            raise UsageError(problem)
        if key in ("plot", "bode", "animate"):  # before any work: the figure needs matplotlib
            require("matplotlib", option)
        if key == "save":
            from netlistdyn.io.exports import FORMATS  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            suffix = os.path.splitext(path)[1].lower()
            if suffix not in FORMATS:
                raise UsageError(f"--save {path}: unknown format {suffix!r}; use one of {', '.join(FORMATS)}")
        real = STDOUT if path == STDOUT else os.path.realpath(path)
        if real in seen:
            raise UsageError(f"{seen[real]} and {option} both write {path}")
        seen[real] = option
        if path != STDOUT:
            given.append((option, path))
    if not given:
        return
    for source in input_files(inputs):
        for option, path in given:
            if same_file(path, source):
                raise UsageError(
                    f"{option} {path}: is {source}, an input of this command; refusing to overwrite it"
                )


def input_files(inputs: tuple[str, ...]) -> list[str]:
    """The files the command reads: each input, and the ``.include``/``.lib`` files of netlists."""
    from netlistdyn.frontend.parser import netlist_files  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

    files: list[str] = []
    for source in inputs:
        if source == DASH:
            files += [str(p) for p in netlist_files(STDIN_NAME, stdin_text())]
        elif os.path.splitext(source)[1].lower() in MODEL_SUFFIXES:
            files.append(source)
        else:
            files += [str(p) for p in netlist_files(source)]
    return files


def same_file(a: str, b: str) -> bool:
    """True when paths ``a`` and ``b`` name one existing file (after links, hard or symbolic)."""
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (an output not yet written): not the same
        return False


def parse_netlist(netlist: str, overrides: dict[str, float] | None = None, text: str | None = None) -> Any:
    """Parse a netlist file, or standard input for ``-`` (``text``: stdin already read)."""
    from netlistdyn.frontend.parser import parse_file, parse_text  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

    if netlist != DASH:  # "-": standard input
        return parse_file(netlist, overrides)
    return parse_text(stdin_text() if text is None else text, STDIN_NAME, overrides)


def stdin_text() -> str:
    """Standard input as a netlist's text (UTF-8, else cp1252, as a file; no NUL bytes).

    Read once per command: the text is kept in the click context, so a
    command may parse the netlist ``-`` more than once.
    """
    ctx = click.get_current_context(silent=True)
    if ctx is not None and "netlistdyn.stdin" in ctx.meta:
        return str(ctx.meta["netlistdyn.stdin"])
    from netlistdyn.frontend.lines import decode  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

    try:
        data = click.get_binary_stream("stdin").read()
    except OSError as exc:
        raise NetlistError(f"cannot read netlist: {exc.strerror or exc}", stdin_loc()) from None
    text = decode(data, stdin_loc())  # as a file given by name: UTF-8, else cp1252/Latin-1
    if ctx is not None:
        ctx.meta["netlistdyn.stdin"] = text
    return text


def stdin_loc() -> Any:
    return SourceLocation(STDIN_NAME, 0)


def write_atomic(path: str, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename (``-``: stdout)."""
    write_text(path, text)


def emit(text: str, out: str | None) -> None:
    """Send a finished document to ``out`` (atomically), stdout, or stderr (:data:`STDERR`)."""
    if out == STDERR:
        sys.stderr.write(text)
        sys.stderr.flush()
    elif out and out != STDOUT:
        write_atomic(out, text)
    else:
        sys.stdout.write(text)
        sys.stdout.flush()


def csv_beside_report(csv_path: str | None, out: str | None, fmt: str) -> str | None:
    """Where the report goes when ``--csv -`` takes standard output: stderr for text, refused for JSON.

    Returns
    -------
    str or None
        ``out`` unchanged, or :data:`STDERR` when the CSV alone must be on stdout (for a pipe).
    """
    if csv_path != STDOUT or (out and out != STDOUT):
        return out
    if fmt == "json":
        raise UsageError("--csv - and the JSON report both write to standard output; give one of them a file")
    return STDERR


def run_guarded(action: Callable[[], int | None]) -> None:
    """Run a command body, turning errors into one-line messages and exit codes.

    Warnings (numpy's floating-point RuntimeWarnings) are caught and, when the command
    succeeded, summed up in one line; a failed command's own message replaces them.
    """
    caught = CaughtWarnings()
    try:
        with caught:
            code = action() or 0
    except NetlistError as exc:
        click.echo(shorten(str(exc)), err=True)
        sys.exit(EXIT_NETLIST)
    except (UsageError, ControlDimension) as exc:
        click.echo(f"netlistdyn: error: {shorten(str(exc))}", err=True)
        sys.exit(EXIT_USAGE)
    except OSError as exc:
        click.echo(f"netlistdyn: error: {exc.filename or ''}: {exc.strerror or exc}", err=True)
        sys.exit(EXIT_USAGE)
    except MemoryError:
        click.echo("netlistdyn: error: out of memory (the model or the request is too large)", err=True)
        sys.exit(EXIT_USAGE)
    except RecursionError:
        if os.environ.get("NETLISTDYN_DEBUG"):
            raise
        click.echo("netlistdyn: internal error: RecursionError: nesting too deep (please report)", err=True)
        sys.exit(EXIT_INTERNAL)
    except Exception as exc:
        if os.environ.get("NETLISTDYN_DEBUG"):
            raise
        message = shorten(f"{type(exc).__name__}: {exc}")
        click.echo(f"netlistdyn: internal error: {message} (please report)", err=True)
        sys.exit(EXIT_INTERNAL)
    summary = caught.line()
    if summary is not None and code == 0:
        click.echo(shorten(summary), err=True)
    sys.exit(code)


def print_warnings(warnings: Any) -> None:
    for warning in warnings:
        click.echo(str(warning), err=True)


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


def path_option(flag: str, help_text: str, dest: str | None = None) -> Callable[[Any], Any]:
    """An optional output-file option."""
    names = (flag, dest) if dest else (flag,)
    return click.option(
        *names, type=click.Path(dir_okay=False, allow_dash=True), default=None, help=help_text
    )


tstop_option = click.option(
    "--tstop", type=POSITIVE, default=None, help="Horizon [s] (default: .tran, else from eigenvalues)."
)


quiet_option = click.option("-q", "--quiet", is_flag=True, help="No progress bar on stderr.")


def load_and_compile(
    netlist: str, params: tuple[str, ...], outputs: list[str] | None, at: tuple[str, ...] = ()
) -> tuple[Any, Any]:
    """Parse with ``--param`` overrides, compile, print the warnings; (netlist, model).

    A nonlinear netlist is replaced by its linearisation at the operating
    point (``--at`` values moved), which is the netlist returned.
    """
    from netlistdyn.formulation.compile import compile_netlist  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

    parsed = parse_netlist(netlist, parse_param_overrides(params))
    if parsed.planar:  # a planar mechanism: the exact Jacobians at its equilibrium
        from netlistdyn.workflows.planar import planar_linear_model  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        model = planar_linear_model(parsed, outputs, parse_param_overrides(at, "--at"))
        print_warnings(model.info.warnings)
        return parsed, model
    if parsed.is_nonlinear:
        from netlistdyn.formulation.operating import linearised  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        parsed, outputs = linearised(parsed, outputs, parse_param_overrides(at, "--at"))
    elif at:
        raise UsageError(
            "--at is for nonlinear netlists (this one is linear: its model is the same everywhere)"
        )
    model = compile_netlist(parsed, outputs)
    print_warnings(model.info.warnings)
    return parsed, model


def load_prepared(
    netlist: str,
    params: tuple[str, ...],
    outputs: tuple[str, ...],
    coordinates: str | None,
    ics: tuple[str, ...] = (),
    extra: tuple[str, ...] = (),
    parsed: Any = None,
) -> tuple[Any, Any]:
    """Parse (unless ``parsed`` is given) and compile for ``--coordinates`` and ``--ic``.

    See :mod:`netlistdyn.coordinates`; ``extra`` are hidden outputs a view needs.
    """
    from netlistdyn.analysis.coordinates import prepare  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

    if parsed is None:
        parsed = parse_netlist(netlist, parse_param_overrides(params))
    if parsed.planar:
        from netlistdyn.workflows.planar import prepare_planar  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        planar = prepare_planar(parsed, list(outputs) or None, coordinates, ics, extra)
        print_warnings(planar.full.info.warnings)
        return parsed, planar
    prepared = prepare(parsed, list(outputs) or None, coordinates, ics, extra)
    print_warnings(prepared.full.info.warnings)
    return parsed, prepared


coordinates_option = click.option(
    "--coordinates",
    default=None,
    metavar="VARS",
    help="Present the model in these variables, e.g. x(b1),x(b2),v(b1),v(b2) or "
    "x(cart),angle(r1),omega(r1) (outputs that together determine the state); 'voltage': "
    "capacitor voltages and inductor currents (as SPICE users think), well scaled.",
)


out_option = click.option(
    "-o",
    "--out",
    type=click.Path(dir_okay=False, allow_dash=True),
    default=None,
    help="Write the report to this file (atomically) instead of stdout ('-': stdout).",
)


SCHEDULER_PATTERN = re.compile(r"(processes|local|dask|(tcp|tls)://[\w.\-\[\]:]+:[0-9]{1,5})")


def check_scheduler(scheduler: str) -> None:
    """Refuse a ``--scheduler`` that is none of the known forms."""
    if not SCHEDULER_PATTERN.fullmatch(scheduler):
        raise UsageError(
            f"--scheduler {shorten(scheduler)!r}: expected processes, dask or a Dask scheduler "
            "address tcp://HOST:PORT"
        )


def available_cpus() -> int:
    """CPUs this process may run on."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):
        return max(os.cpu_count() or 1, 1)


def worker_count(jobs: int, cases: int, oversubscribe: bool, scheduler: str) -> int:
    """Workers for a sweep: no more than the cases, nor (unless told) the CPUs; says when capped."""
    if scheduler.startswith(("tcp://", "tls://")):
        return jobs
    cpus = available_cpus()
    if jobs > cpus and not oversubscribe:
        click.echo(
            f"netlistdyn: note: --jobs {jobs} capped at {cpus}, the CPUs available "
            "(--oversubscribe to run more)",
            err=True,
        )
        jobs = cpus
    return max(1, min(jobs, cases))
