"""Command line: thin wrappers over the pipeline stages.

Exit codes: 0 success, 1 bad netlist, 2 bad command line, 3 validation
mismatch (or a simulation that failed), 4 ngspice missing or unusable,
5 ngspice ran out of time, 70 internal error. Errors are one line on stderr,
never a traceback (set ``NETLISTDYN_DEBUG=1`` to see one).
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import click

from netlistdyn.base import progress
from netlistdyn.base.atomic import STDOUT, install_signal_cleanup
from netlistdyn.base.errors import NetlistError, SourceLocation, UsageError
from netlistdyn.base.processes import cpu_seconds
from netlistdyn.commandline import (
    COUNT,
    DASH,
    EXIT_MISMATCH,
    EXIT_NETLIST,
    EXIT_NO_NGSPICE,
    EXIT_TIMEOUT,
    EXIT_USAGE,
    METHOD_CHOICES,
    MODEL_SUFFIXES,
    NUMBER,
    POSITIVE,
    STDIN_NAME,
    check_outputs,
    check_scheduler,
    coordinates_option,
    csv_beside_report,
    emit,
    format_option,
    load_and_compile,
    load_prepared,
    out_option,
    output_option,
    param_option,
    parse_netlist,
    parse_param_overrides,
    path_option,
    print_warnings,
    quiet_option,
    run_guarded,
    shorten,
    stdin_text,
    tstop_option,
    worker_count,
    write_atomic,
)


class OneLineGroup(click.Group):
    """Click's group, but command-line errors are one line on stderr (exit 2), like ours."""

    def main(self, *args: Any, **kwargs: Any) -> Any:
        if kwargs.get("standalone_mode", True) is False:
            return super().main(*args, **kwargs)
        kwargs["standalone_mode"] = False
        try:
            code = super().main(*args, **kwargs)
        except click.exceptions.NoArgsIsHelpError as exc:
            click.echo(exc.ctx.get_help() if exc.ctx else str(exc), err=True)
            sys.exit(EXIT_USAGE)
        except click.ClickException as exc:
            click.echo(f"netlistdyn: error: {shorten(exc.format_message())}", err=True)
            sys.exit(exc.exit_code)
        except click.exceptions.Abort:
            click.echo("netlistdyn: interrupted", err=True)
            sys.exit(130)
        sys.exit(code if isinstance(code, int) else 0)


@click.group(cls=OneLineGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="netlistdyn")
def main() -> None:
    """Compile SPICE-like netlists to state-space models, analyse and validate them."""
    install_signal_cleanup()


@main.command()
@click.argument("netlist", type=click.Path(exists=True, dir_okay=False, allow_dash=True))
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
@click.option(
    "--control",
    "control_report",
    is_flag=True,
    help="Controllability/observability (PBH), uncontrollable/unobservable modes, "
    "transfer functions with poles, zeros and DC gain.",
)
@click.option("--minimal", is_flag=True, help="Drop the states that do not reach the outputs; say how many.")
@click.option(
    "--symbolic",
    is_flag=True,
    help="Also give A, B, C, D in terms of the element names (sympy, small circuits).",
)
@click.option(
    "--symbols",
    default=None,
    metavar="NAMES",
    help="With --symbolic (implied): keep only these elements symbolic, e.g. R1,C1; "
    "the others take their (--param) values.",
)
@click.option(
    "--canonical",
    is_flag=True,
    help="Controller and observer canonical (companion) forms, as the lecture notes build them.",
)
@path_option(
    "--bode",
    "Plot of the frequency response of every input/output pair over the netlist's .ac range "
    "(PNG, or .svg/.pdf by extension; .csv writes the data: Hz, rad/s, re, im, dB, phase).",
)
@path_option("--save", "Save the model as .json, .npz or .mat (with labels).")
@coordinates_option
@click.option(
    "--at",
    "at",
    multiple=True,
    metavar="NAME=VALUE",
    help="Nonlinear netlists: linearise with this source at VALUE, or this state held at VALUE "
    "(x(bob)=3.14159: the others settle; a point that is not an equilibrium is said). Repeatable.",
)
@quiet_option
@out_option
def analyze(
    netlist: str,
    outputs: tuple[str, ...],
    params: tuple[str, ...],
    fmt: str,
    eig: str,
    control_report: bool,
    minimal: bool,
    symbolic: bool,
    symbols: str | None,
    canonical: bool,
    bode: str | None,
    save: str | None,
    coordinates: str | None,
    at: tuple[str, ...],
    quiet: bool,
    out: str | None,
) -> None:
    """Compile NETLIST to x' = Ax + Bu, y = Cx + Du and analyse its eigenvalues."""
    from netlistdyn.analysis.eigen import analyze_eigenvalues  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
    from netlistdyn.io.report import (  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        canonical_dict,
        canonical_forms,
        canonical_text,
        control_dict,
        control_text,
        model_dict,
        symbolic_dict,
        symbolic_text,
        text_report,
        to_json,
    )

    def body() -> int:
        check_outputs((netlist,), bode=bode, save=save, out=out)
        from netlistdyn.workflows.large import descriptor_wanted  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        early = parse_netlist(netlist, parse_param_overrides(params))
        if descriptor_wanted(early, "auto"):  # large circuit: sparse descriptor form
            explicit_only = (
                ("--control", control_report),
                ("--minimal", minimal),
                ("--symbolic", symbolic or symbols is not None),
                ("--canonical", canonical),
                ("--bode", bode),
                ("--save", save),
                ("--coordinates", coordinates is not None),
            )
            return _analyze_descriptor(early, outputs, fmt, out, [f for f, on in explicit_only if on])

        stages = contextlib.ExitStack()
        bar = stages.enter_context(progress.bar("analyze", 2, quiet, unit="stage"))
        change = None
        if coordinates is not None:
            if symbolic or symbols is not None:
                raise UsageError(
                    "--symbolic shows the compiler's states; it cannot be combined with --coordinates"
                )
            parsed, prepared = load_prepared(netlist, params, outputs, coordinates)
            model, change = prepared.model, prepared.change
        else:
            parsed, model = load_and_compile(netlist, params, list(outputs) or None, at)
        bar.update()
        notes: list[str] = []
        data_error = 0.0
        sym = None
        if symbolic or symbols is not None:
            if minimal:
                raise UsageError("--symbolic shows the compiled model; it cannot be combined with --minimal")
            if parsed.planar:
                raise UsageError(
                    "--symbolic is not available for planar mechanisms (A, B are numeric Jacobians)"
                )
            from netlistdyn.formulation.symbolic import symbolic_model  # noqa: PLC0415 (deferred, imports sympy: optional symbolic extra)

            keep = None if symbols is None else [n.strip() for n in symbols.split(",") if n.strip()]
            sym = symbolic_model(parsed, list(outputs) or list(model.outputs), keep)
        if minimal or control_report:
            from netlistdyn.analysis import control  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            if model.nstates > control.CONTROL_STATE_LIMIT:
                raise UsageError(
                    f"--control and --minimal are for models of up to {control.CONTROL_STATE_LIMIT} states"
                )
            structure = control.structure(model) if control_report else None
            if minimal:
                full = model
                model, reduction = control.minimal_realisation(model)
                dropped = full.nstates - model.nstates
                gone = sorted([*reduction.uncontrollable, *reduction.unobservable], key=abs)
                notes.append(
                    f"--minimal dropped {dropped} state(s)"
                    + (f" (modes {', '.join(f'{v:.6g}' for v in gone)})" if dropped else "")
                )
                if dropped:  # eigenvalue errors must cover the reduction's own backward error
                    data_error = reduction.data_error
                structure = control.structure(model) if control_report else None
            tfs = control.transfer_functions(model) if control_report else []
        analysis = (
            None
            if eig == "none"
            else analyze_eigenvalues(model.A_sparse, eig, data_error, pencil=model.pencil)
        )
        bar.update()
        stages.close()
        forms = canonical_forms(model) if canonical else None
        if save:
            from netlistdyn.io.exports import save_model  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            save_model(model, save)
        response = None
        if bode:
            from netlistdyn.io.bode import bode as frequency_data  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
            from netlistdyn.io.bode import bode_csv  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
            from netlistdyn.io.plots import ac_range, bode_plot  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            response = frequency_data(model, ac_range(parsed))
            if bode.lower().endswith(".csv"):
                write_atomic(bode, bode_csv(response))
            else:
                bode_plot(response, bode, model.title)
        if fmt == "json":
            doc = model_dict(model, analysis)
            doc["netlist"] = netlist
            if response is not None:
                from netlistdyn.io.bode import bode_dict  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

                doc["frequency_response"] = bode_dict(response)
            if control_report:
                doc["control"] = control_dict(structure, tfs)
            if forms is not None:
                doc["canonical"] = canonical_dict(forms)
            if sym is not None:
                doc["symbolic"] = symbolic_dict(sym)
            if notes:
                doc["notes"] = notes
            if change is not None:
                from netlistdyn.analysis.coordinates import change_dict  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

                doc["coordinates"] = change_dict(change)
            emit(to_json(doc), out)
        else:
            text = text_report(model, analysis, netlist, parsed)
            if change is not None:
                from netlistdyn.analysis.coordinates import change_text  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

                text += change_text(change)
            if control_report:
                text += control_text(structure, tfs)
            if forms is not None:
                text += canonical_text(model, forms)
            if sym is not None:
                text += symbolic_text(sym)
            text += "".join(f"note: {n}\n" for n in notes)
            emit(text, out)
        return 0

    run_guarded(body)


@main.command()
@click.argument("netlist", type=click.Path(exists=True, dir_okay=False, allow_dash=True))
@param_option
@click.option(
    "--at",
    "at",
    multiple=True,
    metavar="NAME=VALUE",
    help="Solve with this independent source at VALUE instead of its DC value, or this state held "
    "at VALUE (the drift f(x0, u0) is printed when the point is not an equilibrium). Repeatable.",
)
@format_option
@out_option
@quiet_option
def op(
    netlist: str, params: tuple[str, ...], at: tuple[str, ...], fmt: str, out: str | None, quiet: bool
) -> None:
    """DC operating point of NETLIST (capacitors open, inductors short): Newton with
    junction limiting, then gmin stepping, then source stepping, as SPICE does."""

    def body() -> int:
        check_outputs((netlist,), out=out)
        from netlistdyn.formulation.operating import operating_point, point_dict, point_text  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.io.report import to_json  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        parsed = parse_netlist(netlist, parse_param_overrides(params))
        print_warnings(parsed.warnings)
        if parsed.planar:
            from netlistdyn.workflows import planar  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            where = planar.planar_point(parsed, parse_param_overrides(at, "--at"))
            doc = {"netlist": netlist, "operating_point": planar.point_dict(where)}
            emit(to_json(doc) if fmt == "json" else planar.point_text(where, parsed), out)
            return 0
        point = operating_point(parsed, parse_param_overrides(at, "--at"))
        if fmt == "json":
            emit(to_json({"netlist": netlist, "operating_point": point_dict(point, parsed)}), out)
        else:
            emit(point_text(point, parsed), out)
        return 0

    run_guarded(body)


@main.command()
@click.argument("netlist", type=click.Path(exists=True, dir_okay=False, allow_dash=True))
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
@tstop_option
@click.option("--tstep", type=POSITIVE, default=None, help="Output step [s].")
@click.option(
    "--rtol",
    type=POSITIVE,
    default=1e-3,
    show_default=True,
    help="Pass threshold: max error relative to each waveform's peak.",
)
@click.option(
    "--timeout",
    type=POSITIVE,
    default=600.0,
    show_default=True,
    help="Seconds allowed to ngspice (exit 5 when exceeded).",
)
@click.option(
    "--ngspice-reltol",
    type=POSITIVE,
    default=None,
    help="ngspice's reltol for the reference run (default 1e-9, relaxed to 1e-7 and 1e-5 if ngspice aborts).",
)
@click.option(
    "--ngspice-maxstep",
    type=POSITIVE,
    default=None,
    help="ngspice's maximum step [s] (default: from the eigenvalues, bounding the trapezoidal "
    "rule's phase error to 1e-6 over the horizon).",
)
@path_option("--plot", "Write a plot of both responses (PNG, or .svg/.pdf by extension).")
@click.option(
    "--pz/--no-pz",
    default=True,
    show_default=True,
    help="Compare ngspice's .pz poles for models of up to 6 states (informative).",
)
@format_option
@quiet_option
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
    ngspice_reltol: float | None,
    ngspice_maxstep: float | None,
    plot: str | None,
    pz: bool,
    fmt: str,
    quiet: bool,
    out: str | None,
) -> None:
    """Run NETLIST through ngspice and the compiled model and compare the responses.

    Exit status 0 when every output agrees within --rtol of its peak, 3 when not,
    4 when ngspice is missing or unusable or fails on the file (inconclusive), 5 when it ran
    out of --timeout.
    """
    from netlistdyn.spice.ngspice import ngspice_missing  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

    def body() -> int:
        check_outputs((netlist,), plot=plot, out=out)
        missing = ngspice_missing()
        if missing:
            click.echo(f"netlistdyn: {missing}", err=True)
            return EXIT_NO_NGSPICE
        from netlistdyn.devices.units import signal_units  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.io.report import to_json, validation_dict, validation_text  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.workflows.pipelines import NetlistText, validation_pipeline  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        # "-": the text of standard input (ngspice reads it from a temporary copy).
        source = NetlistText(STDIN_NAME, stdin_text()) if netlist == DASH else netlist
        with progress.bar("validate (ngspice and model)", None, quiet, unit="run"):
            result = validation_pipeline(
                source,
                parse_param_overrides(params),
                list(outputs) or None,
                parse_param_overrides(model_params),
                tstop,
                tstep,
                rtol,
                timeout,
                pz,
                {"reltol": ngspice_reltol, "maxstep": ngspice_maxstep},
                warn=lambda w: click.echo(str(w), err=True),
            )
        report = result.report
        if report.spice.status == "unusable":
            click.echo(f"netlistdyn: {report.spice.message}", err=True)
            return EXIT_NO_NGSPICE
        if report.spice.status == "timeout":
            click.echo(f"netlistdyn: {report.spice.message} (raise it with --timeout)", err=True)
            return EXIT_TIMEOUT
        if plot and report.spice.ok:
            from netlistdyn.io.plots import validation_plot  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            validation_plot(report, plot, signal_units(parse_netlist(netlist), result.outputs), result.title)
        if fmt == "json":
            emit(to_json(validation_dict(report, result.title, result.reference_accuracy)), out)
        else:
            emit(validation_text(report, result.title), out)
        if not report.spice.ok:  # inconclusive: ngspice itself failed on the file
            return EXIT_NO_NGSPICE
        return 0 if report.passed else EXIT_MISMATCH

    run_guarded(body)


@main.command()
@click.argument("netlist", type=click.Path(exists=True, dir_okay=False, allow_dash=True))
@output_option
@param_option
@tstop_option
@click.option("--tstep", type=POSITIVE, default=None, help="Output step [s] (default: tstop/1000).")
@click.option(
    "--method",
    type=click.Choice([*METHOD_CHOICES, "euler", "descriptor"]),
    default="auto",
    show_default=True,
    help="exact (dense expm, small models), rational (sparse Padé, large models), krylov, "
    "a scipy solve_ivp method, euler (forward Euler at a fixed --step, with its error against the "
    "exact solution), or descriptor (sparse MNA form, power grids); auto: exact up to 400 states, "
    "descriptor when the circuit is stiff relative to the output step (or very large), else rational.",
)
@click.option(
    "--step",
    type=POSITIVE,
    default=None,
    help="The fixed step of --method euler [s]; the output times are its steps.",
)
@click.option("--rtol", type=POSITIVE, default=1e-10, show_default=True, help="Relative tolerance.")
@click.option("--atol", type=POSITIVE, default=None, help="Absolute tolerance (solve_ivp methods).")
@click.option(
    "--ic",
    "ics",
    multiple=True,
    metavar="NAME=VALUE",
    help="Initial condition on a state (q(C1)=1e-6) or a physical variable (angle(r1)=-0.01, "
    "x(cart)=0, v(b1)=0.5, omega(r1)=0); states no condition involves start at 0.",
)
@coordinates_option
@click.option("--force", is_flag=True, help="Run an explicit method on a stiff model anyway.")
@click.option(
    "--superpose",
    is_flag=True,
    help="Linear superposition: split the independent sources into --jobs groups (sources sharing "
    "breakpoints together), simulate each group alone (the others at 0; the initial state in one "
    "more job) as independent tasks on --scheduler, and sum the outputs. Each job runs at rtol/jobs "
    "and reports its own error estimate; the sum's estimate is the sum of theirs (the descriptor "
    "form's jobs report none). Linear netlists only.",
)
@click.option(
    "--jobs",
    type=COUNT,
    default=None,
    help="--superpose: number of source groups (default 2); the local workers are capped at the CPUs "
    "unless --oversubscribe.",
)
@click.option("--oversubscribe", is_flag=True, help="--superpose: allow more local workers than CPUs.")
@click.option(
    "--scheduler",
    default=None,
    metavar="processes|dask|tcp://HOST:PORT",
    help="--superpose: where the jobs run, as for sweep: this machine's process pool (default), a local "
    "Dask cluster, or a running Dask scheduler (needs dask[distributed]).",
)
@path_option("--csv", "Write the outputs as CSV.", "csv_path")
@path_option("--plot", "Write a plot (PNG, or the format of the file's extension: .svg, .pdf).")
@path_option("--animate", "Animate a mechanical netlist into a .gif (or .mp4 with ffmpeg).")
@click.option("--fps", type=NUMBER, default=25.0, show_default=True, help="--animate: frames per second.")
@click.option(
    "--speed",
    type=NUMBER,
    default=1.0,
    show_default=True,
    help="--animate: simulated seconds per second shown.",
)
@click.option("--frame-size", default="640x360", show_default=True, metavar="WxH", help="--animate: pixels.")
@click.option(
    "--geometry",
    multiple=True,
    metavar="KEY=VALUE",
    help="--animate: spacing=M (rest distance between nodes) or rod_scale=F (drawn/true rod length).",
)
@format_option
@quiet_option
@out_option
def simulate(
    netlist: str,
    outputs: tuple[str, ...],
    params: tuple[str, ...],
    tstop: float | None,
    tstep: float | None,
    method: str,
    step: float | None,
    rtol: float,
    atol: float | None,
    ics: tuple[str, ...],
    coordinates: str | None,
    force: bool,
    superpose: bool,
    jobs: int | None,
    oversubscribe: bool,
    scheduler: str | None,
    csv_path: str | None,
    plot: str | None,
    animate: str | None,
    fps: float,
    speed: float,
    frame_size: str,
    geometry: tuple[str, ...],
    fmt: str,
    quiet: bool,
    out: str | None,
) -> None:
    """Time response of NETLIST to its own source waveforms, from the DC operating point
    (with .tran ... UIC: from the IC= and .ic values, else zero; or from --ic).

    Exit status 3 when the method refused, failed or diverged (the message says why).
    """

    def body() -> int:
        from netlistdyn.analysis.coordinates import select_outputs  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.analysis.validity import rod_angles, validity_warnings  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.base.formatting import eng  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.devices.units import signal_units  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.io.report import simulation_csv, simulation_dict, simulation_summary, to_json  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.simulation.foh import input_signals  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.simulation.integrators import EXACT_LIMIT  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.workflows.large import descriptor_wanted, simulate_descriptor_wanted  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.workflows.pipelines import simulation_pipeline  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        check_outputs((netlist,), csv=csv_path, plot=plot, animate=animate, out=out)
        report_to = csv_beside_report(csv_path, out, fmt)
        split = _superpose_options(superpose, jobs, oversubscribe, scheduler, coordinates, animate)
        parsed = parse_netlist(netlist, parse_param_overrides(params))
        if split is not None:
            from netlistdyn.workflows.superpose import check_linear  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            check_linear(parsed)
        # Large, or (auto) stiff relative to the output step when no option needs the explicit
        # model (--ic names its states, --coordinates and --animate its variables): descriptor form.
        plain = split is None and not ics and not coordinates and not animate
        if descriptor_wanted(parsed, method) or (
            plain
            and simulate_descriptor_wanted(parsed, method, list(outputs) or None, tstop, tstep, EXACT_LIMIT)
        ):
            refused = [f for f, on in (("--coordinates", coordinates), ("--animate", animate)) if on]
            if refused:
                raise UsageError(f"{refused[0]} is not available in the sparse descriptor form")
            return _simulate_descriptor(
                parsed,
                netlist,
                outputs,
                tstop,
                tstep,
                rtol,
                ics,
                csv_path,
                plot,
                fmt,
                report_to,
                quiet,
                split,
            )
        angles = rod_angles(parsed)
        extra = list(angles)
        if animate:
            from netlistdyn.io.animate import animation_options, position_variables  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            view = animation_options(animate, fps, speed, frame_size, geometry)
            if parsed.planar:
                from netlistdyn.io import planar_animate  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

                extra += planar_animate.position_variables(parsed)
            else:
                extra += position_variables(parsed)
        parsed, prepared = load_prepared(netlist, params, outputs, coordinates, ics, tuple(extra), parsed)
        full = prepared.full
        if split is not None:
            from netlistdyn.workflows.superpose import explicit_task  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            task, span = explicit_task(parsed, full, tstop, tstep, method, rtol, atol, prepared.x0, force)
            run = _run_superposed(task, span, split, quiet)
        else:
            with progress.bar("simulate", 100, quiet, unit="%") as bar:
                run = simulation_pipeline(
                    parsed,
                    full,
                    tstop,
                    tstep,
                    method,
                    rtol,
                    atol,
                    prepared.x0,
                    force,
                    progress.fraction_callback(bar),
                    warn=lambda w: click.echo(str(w), err=True),
                    step=step,
                )
        horizon = run.horizon
        unverified = run.status == "unverified"  # numbers written, but not vouched for: exit 3
        if not run.ok and not unverified:
            click.echo(f"netlistdyn: {run.method} {run.status}: {run.message}", err=True)
            return EXIT_MISMATCH
        if unverified:
            click.echo(f"netlistdyn: warning: {run.method} result unverified: {run.message}", err=True)
        model = select_outputs(full, prepared.shown)
        result = replace(
            run,
            values=run.values[:, [full.outputs.index(n) for n in prepared.shown]],
            outputs=tuple(model.outputs),
            units=signal_units(parsed, model.outputs),
        )
        # a planar run integrates the exact equations: no small-angle validity to warn about
        warnings = (
            [] if parsed.planar else validity_warnings(run.time, run.values, full.outputs, angles, run.eigen)
        )
        for warning in warnings:
            click.echo(f"netlistdyn: warning: {warning}", err=True)
        if csv_path:
            write_atomic(csv_path, simulation_csv(result))
        if plot:
            from netlistdyn.io.plots import simulation_plot  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            simulation_plot(result, plot)
        if animate:
            from netlistdyn.io.animate import Animation  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            signals = input_signals(parsed, horizon.tstep, horizon.tstop)
            if parsed.planar:
                from netlistdyn.io.planar_animate import PlanarAnimation  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

                movie: Animation = PlanarAnimation(
                    parsed, run.time, run.values, full.outputs, signals(run.time), view
                )
            else:
                movie = Animation(parsed, run.time, run.values, full.outputs, signals(run.time), view)
            frames = movie.save(animate)
            click.echo(f"netlistdyn: {animate}: {frames} frames at {fps:g} fps", err=True)
        if fmt == "json":
            doc = simulation_dict(result, netlist)
            doc["warnings"] = warnings
            if prepared.change is not None:
                from netlistdyn.analysis.coordinates import change_dict  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

                doc["coordinates"] = change_dict(prepared.change)
            emit(to_json(doc), report_to)
        else:
            summary = (
                f"{parsed.title}\nsimulated 0..{eng(horizon.tstop, 's')}, {result.time.size} points "
                f"every {eng(horizon.tstep, 's')} ({horizon.source}); "
                f"method {result.method} ({result.setting}) in {result.seconds:.3f} s\n"
                f"start: {result.start}\n"
            )
            text = summary + simulation_summary(result)
            if (result.method == "euler" or parsed.planar) and result.message:  # error, energy drift
                text += result.message + "\n"
            if prepared.change is not None:
                from netlistdyn.analysis.coordinates import change_text  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

                text += change_text(prepared.change)
            emit(text, report_to)
        return EXIT_MISMATCH if unverified else 0

    run_guarded(body)


@main.command()
@click.argument("netlist", type=click.Path(exists=True, dir_okay=False, allow_dash=True))
@output_option
@param_option
@tstop_option
@click.option("--points", type=COUNT, default=1000, show_default=True, help="Grid intervals for scoring.")
@click.option(
    "--budget",
    type=POSITIVE,
    default=120.0,
    show_default=True,
    help="CPU seconds for the whole bench (its own and each row's process); rows that do not fit "
    "are stopped when their own CPU time runs out, and reported.",
)
@click.option(
    "--repeats", type=COUNT, default=3, show_default=True, help="Timed repetitions at most (median)."
)
@click.option(
    "--timeout", type=POSITIVE, default=600.0, show_default=True, help="CPU seconds allowed to any one run."
)
@click.option(
    "--method",
    "methods",
    multiple=True,
    type=click.Choice(list(METHOD_CHOICES[1:])),
    help="Our methods to run (repeatable; default: all that apply).",
)
@click.option("--ngspice/--no-ngspice", default=True, show_default=True, help="Include ngspice rows.")
@click.option(
    "--reference-rtol",
    type=POSITIVE,
    default=1e-12,
    show_default=True,
    help="Tolerance of the rational run that checks the reference.",
)
@click.option(
    "--stream",
    is_flag=True,
    help="Write each row as it is done (with --format json: JSON lines), also to -o FILE (not atomic).",
)
@path_option("--plot", "Log-log plot of error against time (PNG, or .svg/.pdf by extension).")
@format_option
@quiet_option
@out_option
def bench(
    netlist: str,
    outputs: tuple[str, ...],
    params: tuple[str, ...],
    tstop: float | None,
    points: int,
    budget: float,
    repeats: int,
    timeout: float,
    methods: tuple[str, ...],
    ngspice: bool,
    reference_rtol: float,
    stream: bool,
    plot: str | None,
    fmt: str,
    quiet: bool,
    out: str | None,
) -> None:
    """Error against run time for our integration methods and for ngspice, on NETLIST, within a budget."""
    started = cpu_seconds()  # the budget is CPU seconds (this process and its rows')

    def body() -> int:
        from netlistdyn.analysis.eigen import analyze_eigenvalues  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.circuit.probes import parse_probe  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.io.report import (  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
            bench_dict,
            bench_head_dict,
            bench_line,
            bench_row_dict,
            bench_text,
            bench_text_head,
            bench_text_row,
            bench_text_tail,
            to_json,
        )
        from netlistdyn.simulation.foh import choose_horizon  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.spice.bench import MAX_POINTS, run_bench  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.spice.validate import spice_settings_for  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        if points > MAX_POINTS:
            raise UsageError(f"--points {points}: more than {MAX_POINTS:,} grid intervals")
        check_outputs((netlist,), plot=plot, out=out)
        parsed, model = load_and_compile(netlist, params, list(outputs) or None)
        if not parsed.sources:
            raise NetlistError(
                "bench needs an independent source: without one the response from rest is zero",
                _whole_file(parsed),
            )
        probes = [parse_probe(name, parsed) for name in model.outputs]
        eig = analyze_eigenvalues(
            model.A_sparse, "auto" if model.nstates <= 1000 else "extreme", pencil=model.pencil
        )
        horizon = choose_horizon(parsed, eig, tstop, None)
        # Text goes out row by row on stdout (or with --stream); JSON lines only with --stream.
        live = stream or (fmt == "text" and (not out or out == STDOUT))
        with (
            progress.bar("bench", None, quiet, unit="row") as bar,
            _stream("jsonl" if live else fmt, out) as write,
        ):

            def send(text: str) -> None:
                if write is not None:
                    with bar.external_write_mode():
                        write(text.rstrip("\n"))

            def started_row(label: str, done: int, total: int) -> None:
                bar.total = total or None
                bar.n = done
                bar.set_description(f"bench: {label}")

            report = run_bench(
                parsed,
                model,
                probes,
                horizon,
                spice_settings_for(horizon, eig),
                points,
                repeats,
                timeout,
                methods or None,
                ngspice,
                reference_rtol,
                budget,
                started,
                on_reference=lambda head: send(
                    bench_text_head(head)
                    if fmt == "text"
                    else bench_line({"record": "head", **bench_head_dict(head)})
                ),
                on_start=started_row,
                on_row=lambda row: send(
                    bench_text_row(row)
                    if fmt == "text"
                    else bench_line({"record": "row", **bench_row_dict(row)})
                ),
            )
            if live:
                tail = bench_dict(report)
                send(
                    bench_text_tail(report)
                    if fmt == "text"
                    else bench_line(
                        {"record": "end", "elapsed": tail["elapsed"], "load_average": tail["load_average"]}
                    )
                )
        if plot:
            from netlistdyn.io.plots import bench_plot  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            bench_plot(report, plot)
        if not live:
            emit(to_json(bench_dict(report)) if fmt == "json" else bench_text(report), out)
        return 0

    run_guarded(body)


@main.command()
@click.argument("netlist", type=click.Path(exists=True, dir_okay=False, allow_dash=True))
@click.option(
    "--param",
    "params",
    multiple=True,
    metavar="NAME=V1,V2|log:a:b:n|lin:a:b:n",
    help="Values of a .param to sweep (repeatable; equal-length lists go together).",
)
@output_option
@click.option(
    "--jobs",
    type=COUNT,
    default=1,
    show_default=True,
    help="Parallel processes (workers); capped at this machine's CPUs unless --oversubscribe.",
)
@click.option("--oversubscribe", is_flag=True, help="Allow --jobs above the number of CPUs.")
@click.option(
    "--max-cases",
    type=click.IntRange(min=1),
    default=100_000,
    show_default=True,
    help="Refuse sweeps with more cases than this (counted before any runs).",
)
@click.option(
    "--scheduler",
    default="processes",
    show_default=True,
    metavar="processes|dask|tcp://HOST:PORT",
    help="Where the cases run: this machine's process pool, a local Dask cluster of --jobs "
    "workers, or a running Dask scheduler (needs dask[distributed]).",
)
@click.option(
    "--eig",
    type=click.Choice(["auto", "all", "extreme"]),
    default="auto",
    show_default=True,
    help="Eigenvalues per case: all (dense, with error estimates), extreme (ARPACK: the slowest "
    "and fastest few, much cheaper for large models), auto by size.",
)
@path_option("--plot", "Root-locus plot of the eigenvalues (PNG, or .svg/.pdf by extension).")
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["text", "json", "jsonl"]),
    default="text",
    show_default=True,
    help="jsonl: one JSON object per case, written as each case finishes (a stopped sweep keeps them).",
)
@quiet_option
@out_option
def sweep(
    netlist: str,
    params: tuple[str, ...],
    outputs: tuple[str, ...],
    jobs: int,
    oversubscribe: bool,
    max_cases: int,
    scheduler: str,
    eig: str,
    plot: str | None,
    fmt: str,
    quiet: bool,
    out: str | None,
) -> None:
    """Eigenvalues and stability for each case of a parameter sweep (compiled once).

    Eigenvalues are sorted in the first case and then follow each mode from case to case.
    Exit status 1 when every case fails (the first failure is printed).
    """

    def body() -> int:
        from netlistdyn.io.report import sweep_record_json, sweep_text, to_json  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.workflows.sweep import SweepSource, expand_cases, iter_sweep  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        check_outputs((netlist,), plot=plot, out=out)
        check_scheduler(scheduler)
        # "-": standard input, read once; every case re-reads its text (as a file's).
        source = SweepSource(STDIN_NAME, stdin_text()) if netlist == DASH else SweepSource.read(netlist)
        if params:
            cases = expand_cases(params, max_cases)
        else:  # the netlist's own .step param lines (LTspice)
            cases = parse_netlist(netlist).step_cases()
            if not cases:
                raise UsageError("sweep needs --param NAME=VALUES (or .step param lines in the netlist)")
            if len(cases) > max_cases:
                raise UsageError(
                    f"the .step lines make {len(cases):,} cases, more than the limit of {max_cases:,} "
                    "(raise it with --max-cases)"
                )
        workers = worker_count(jobs, len(cases), oversubscribe, scheduler)
        result = []
        with progress.bar("sweep", len(cases), quiet, unit="case") as bar, _stream(fmt, out) as write:
            for record in iter_sweep(source, cases, list(outputs) or None, workers, scheduler, eig):
                result.append(record)
                if write is not None:
                    write(sweep_record_json(record))
                bar.update()
        failed = [case for case in result if "error" in case]
        if failed and len(failed) == len(result):
            first = shorten(str(failed[0]["error"]))
            click.echo(f"{first} (every one of the {len(result)} cases failed)", err=True)
            return EXIT_NETLIST
        if plot:
            from netlistdyn.io.plots import sweep_plot  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            sweep_plot(result, plot)
        if fmt == "json":
            emit(to_json({"netlist": netlist, "cases": result}), out)
        elif fmt == "text":
            emit(sweep_text(result), out)
        return 0

    run_guarded(body)


def _whole_file(parsed: Any) -> Any:
    """The location of a netlist as a whole (its title line)."""
    return SourceLocation(getattr(parsed, "path", None) or "<netlist>", 1)


@contextlib.contextmanager
def _stream(fmt: str, out: str | None) -> Iterator[Callable[[str], None] | None]:
    """For ``--format jsonl``: a function writing one line and flushing it (to ``out`` or stdout).

    Streaming is not atomic by design: each finished case is on disk at once,
    so a sweep stopped half way keeps the cases it finished.
    """
    if fmt != "jsonl":
        yield None
        return
    to_file = bool(out) and out != "-"  # "-" is stdout, as everywhere
    handle = open(out, "w", encoding="utf-8") if to_file else sys.stdout  # type: ignore[arg-type]  # noqa: SIM115
    try:

        def write(line: str) -> None:
            handle.write(line + "\n")
            handle.flush()

        yield write
    finally:
        if to_file:
            handle.close()


def load_block(path: str, params: tuple[str, ...], outputs: tuple[str, ...]) -> Any:
    """A model for ``connect``: a netlist compiled with its options, or a model saved by ``--save``."""
    if Path(path).suffix.lower() in MODEL_SUFFIXES:
        if params or outputs:
            raise UsageError(f"{path} is a saved model: --param/--output apply to netlists only")
        from netlistdyn.io.exports import load_model  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        return load_model(path)
    return load_and_compile(path, params, list(outputs) or None)[1]


@main.command()
@click.argument("how", type=click.Choice(["series", "feedback"]))
@click.argument("first", type=click.Path(exists=True, dir_okay=False))
@click.argument("second", type=click.Path(exists=True, dir_okay=False))
@click.option("--output1", multiple=True, metavar="SPEC", help="Output of FIRST (netlists; repeatable).")
@click.option("--output2", multiple=True, metavar="SPEC", help="Output of SECOND (netlists; repeatable).")
@click.option("--param1", multiple=True, metavar="NAME=VALUE", help=".param override for FIRST.")
@click.option("--param2", multiple=True, metavar="NAME=VALUE", help=".param override for SECOND.")
@click.option(
    "--sign",
    type=click.Choice(["-1", "+1", "1"]),
    default="-1",
    show_default=True,
    help="feedback: u1 = r + sign·y2.",
)
@format_option
@path_option("--save", "Save the connected model as .json, .npz or .mat.")
@out_option
@quiet_option
def connect(
    how: str,
    first: str,
    second: str,
    output1: tuple[str, ...],
    output2: tuple[str, ...],
    param1: tuple[str, ...],
    param2: tuple[str, ...],
    sign: str,
    fmt: str,
    save: str | None,
    out: str | None,
    quiet: bool,
) -> None:
    """Connect two models (netlists or saved models) in series or feedback and analyse the result.

    series: FIRST's outputs drive SECOND's inputs, in order. feedback: FIRST's
    outputs drive SECOND's inputs and SECOND's outputs return to FIRST's
    inputs with SIGN; the closed loop's input is FIRST's, its outputs FIRST's.
    """

    def body() -> int:
        from netlistdyn.analysis.eigen import analyze_eigenvalues  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.io.report import model_dict, text_report, to_json  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
        from netlistdyn.statespace.interconnect import connection_names, feedback, series  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        check_outputs((first, second), save=save, out=out)
        m1 = load_block(first, param1, output1)
        m2 = load_block(second, param2, output2)
        names = (Path(first).stem, Path(second).stem)
        if names[0] == names[1]:
            names = (f"{names[0]}1", f"{names[1]}2")
        model = series(m1, m2, names) if how == "series" else feedback(m1, m2, float(sign), names)
        links = connection_names(m1, m2, how, names, float(sign))
        analysis = analyze_eigenvalues(model.A_sparse, pencil=model.pencil)
        if save:
            from netlistdyn.io.exports import save_model  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

            save_model(model, save)
        if fmt == "json":
            doc = model_dict(model, analysis)
            doc["connections"] = links
            emit(to_json(doc), out)
        else:
            text = text_report(model, analysis, f"{how}({first}, {second})")
            emit(text + "connections:\n" + "".join(f"  {link}\n" for link in links), out)
        return 0

    run_guarded(body)


def _simulate_descriptor(
    parsed: Any,
    netlist: str,
    outputs: tuple[str, ...],
    tstop: float | None,
    tstep: float | None,
    rtol: float,
    ics: tuple[str, ...],
    csv_path: str | None,
    plot: str | None,
    fmt: str,
    out: str | None,
    quiet: bool,
    split: tuple[int, str, bool] | None = None,
) -> int:
    """``simulate`` on the sparse descriptor form (see :mod:`netlistdyn.large`), superposed with ``split``."""
    from netlistdyn.base.formatting import eng  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
    from netlistdyn.io.report import simulation_csv, simulation_dict, simulation_summary, to_json  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
    from netlistdyn.workflows.large import simulate_large  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

    print_warnings(parsed.warnings)
    if split is not None:
        from netlistdyn.workflows.superpose import descriptor_task  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        task, horizon = descriptor_task(parsed, list(outputs) or None, tstop, tstep, ics, rtol)
        result = _run_superposed(task, horizon, split, quiet)
    else:
        with progress.bar("simulate", 100, quiet, unit="%") as bar:
            result = simulate_large(
                parsed,
                list(outputs) or None,
                tstop,
                tstep,
                ics,
                progress.fraction_callback(bar),
                rtol,
                warn=lambda w: click.echo(str(w), err=True),
            )
    unverified = result.status == "unverified"
    if not result.ok and not unverified:
        click.echo(f"netlistdyn: {result.method} {result.status}: {result.message}", err=True)
        return EXIT_MISMATCH
    if unverified:
        click.echo(f"netlistdyn: warning: {result.method} result unverified: {result.message}", err=True)
    if csv_path:
        write_atomic(csv_path, simulation_csv(result))
    if plot:
        from netlistdyn.io.plots import simulation_plot  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

        simulation_plot(result, plot)
    if fmt == "json":
        emit(to_json(simulation_dict(result, netlist)), out)
    else:
        horizon = result.horizon
        summary = (
            f"{parsed.title}\nsimulated 0..{eng(horizon.tstop, 's')}, {result.time.size} points "
            f"every {eng(horizon.tstep, 's')} ({horizon.source}); "
            f"method {result.method} ({result.setting}) in {result.seconds:.3f} s\n"
        )
        emit(summary + simulation_summary(result), out)
    return EXIT_MISMATCH if unverified else 0


def _superpose_options(
    superpose: bool,
    jobs: int | None,
    oversubscribe: bool,
    scheduler: str | None,
    coordinates: str | None,
    animate: str | None,
) -> tuple[int, str, bool] | None:
    """``simulate``'s superposition options as (jobs, scheduler, oversubscribe), None without --superpose."""
    if not superpose:
        options = (("--jobs", jobs), ("--scheduler", scheduler), ("--oversubscribe", oversubscribe))
        given = [f for f, on in options if on]
        if given:
            raise UsageError(f"{given[0]} applies to --superpose only")
        return None
    refused = [f for f, on in (("--coordinates", coordinates), ("--animate", animate)) if on]
    if refused:
        raise UsageError(f"{refused[0]} is not available with --superpose")
    scheduler = scheduler or "processes"
    check_scheduler(scheduler)
    return (jobs or 2), scheduler, oversubscribe


def _run_superposed(task: Any, horizon: Any, split: tuple[int, str, bool], quiet: bool) -> Any:
    """Plan, run and sum the jobs of ``simulate --superpose`` (see :mod:`netlistdyn.superpose`)."""
    from netlistdyn.workflows.superpose import plan, superpose  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

    count, scheduler, oversubscribe = split
    jobs = plan(task.netlist, count, task.tstep, task.tstop, bool(task.ics) or task.x0 is not None)
    workers = worker_count(count, len(jobs), oversubscribe, scheduler)
    with progress.bar("superpose", len(jobs), quiet, unit="job") as bar:
        result, warnings = superpose(task, jobs, horizon, workers, scheduler, bar.update)
    print_warnings(warnings)
    return result


def _analyze_descriptor(
    parsed: Any, outputs: tuple[str, ...], fmt: str, out: str | None, refused: list[str]
) -> int:
    """``analyze`` of a large circuit: the descriptor form's size, states and slowest modes."""
    from netlistdyn.io.report import to_json  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)
    from netlistdyn.workflows.large import DESCRIPTOR_UNKNOWNS, analyze_large, analyze_text  # noqa: PLC0415 (deferred so --help and other commands do not load numpy/scipy)

    if refused:
        raise UsageError(
            f"{refused[0]} needs the explicit model, which is not formed above {DESCRIPTOR_UNKNOWNS} "
            "unknowns (the sparse descriptor form is analysed instead)"
        )
    print_warnings(parsed.warnings)
    report = analyze_large(parsed, list(outputs) or None)
    emit(to_json(report) if fmt == "json" else analyze_text(report), out)
    return 0


if __name__ == "__main__":  # pragma: no cover
    main()
