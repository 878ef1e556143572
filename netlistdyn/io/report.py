"""Rendering a compiled model and its analysis: text for people, JSON for programs.

Renderers are pure functions returning strings; the CLI decides where they go.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from typing import Any

from netlistdyn.analysis import control
from netlistdyn.analysis.eigen import EigenAnalysis
from netlistdyn.base.errors import UsageError
from netlistdyn.base.formatting import element_value, eng, format_matrix
from netlistdyn.devices.units import signal_units
from netlistdyn.io.display import simulation_rows
from netlistdyn.io.exports import matrix_json
from netlistdyn.statespace.model import StateSpaceModel

#: Largest model whose matrices are printed in text and written as nested lists in JSON.
DENSE_OUTPUT_LIMIT = 2000
#: Largest matrix dimension printed in the text report.
TEXT_MATRIX_LIMIT = 16


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def model_dict(model: StateSpaceModel, eig: EigenAnalysis | None) -> dict[str, Any]:
    """The JSON document for ``analyze --format json``.

    Matrices are nested lists of rows up to :data:`DENSE_OUTPUT_LIMIT`
    states, and COO triplets (``{"format": "coo", ...}``) above it.
    """
    dense_ok = model.nstates <= DENSE_OUTPUT_LIMIT
    doc: dict[str, Any] = {
        "title": model.title,
        "states": list(model.states),
        "inputs": list(model.inputs),
        "outputs": list(model.outputs),
        "nstates": model.nstates,
        "ninputs": model.ninputs,
        "noutputs": model.noutputs,
        "A": matrix_json(model.A_sparse, dense_ok),
        "B": matrix_json(model.B_sparse, dense_ok),
        "C": matrix_json(model.C_sparse, dense_ok),
        "D": matrix_json(model.D_sparse, True),
    }
    if model.has_input_derivative:
        doc["D1"] = matrix_json(model.D1_sparse, True)
    info = model.info
    doc["order"] = info.order
    doc["excess_elements"] = [
        {"element": e.element, "reason": e.reason, "members": list(e.members)} for e in info.excess
    ]
    doc["state_shifts"] = {s.state: dict(s.coefficients) for s in info.shifts}
    if eig is not None:
        doc["eigenvalues"] = [[m.value.real, m.value.imag] for m in eig.modes]
        doc["modes"] = [
            {
                "re": m.value.real,
                "im": m.value.imag,
                "natural_frequency": m.natural_frequency,
                "natural_frequency_hz": m.natural_frequency / (2 * math.pi),
                "damping": _finite(m.damping),
                "time_constant": _finite(m.time_constant),
                "abs_error": _finite(m.abs_error),
                "rel_error": _finite(m.rel_error),
            }
            for m in eig.modes
        ]
        doc["eigenvalues_complete"] = eig.complete
        doc["eigen_method"] = eig.method
        doc["stability"] = eig.verdict
        doc["stiffness_ratio"] = eig.stiffness_ratio
    doc["warnings"] = [str(w) for w in info.warnings] + (list(eig.warnings) if eig else [])
    return doc


def _clean(obj: Any) -> Any:
    """Non-finite floats as None, tuples as lists, recursively (JSON has no inf/nan)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    return obj


def to_json(doc: dict[str, Any]) -> str:
    """Serialise with non-finite numbers as null (JSON has no inf/nan)."""
    body = ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}" for k, v in _clean(doc).items())
    return "{\n" + body + "\n}\n"


def _unit_of_state(name: str) -> str:
    return {
        "q": "C",
        "i": "A",
        "p": "momentum",
        "f": "force",
        "x": "displacement",
        "v": "V or m/s",
        "angle": "rad",
        "omega": "rad/s",
    }.get(name.split("(", 1)[0].rsplit(".", 1)[-1], "")  # plant.q(C1) after connect


def text_report(model: StateSpaceModel, eig: EigenAnalysis | None, path: str, netlist: Any = None) -> str:
    """The human-readable ``analyze`` report (``netlist``, when given, tells V from m/s in v(...) states)."""
    told = dict(zip(model.states, signal_units(netlist, model.states), strict=True)) if netlist else {}

    def unit(state: str) -> str:
        return told.get(state) or _unit_of_state(state)

    out = [f"{model.title}", f"netlist: {path}", ""]
    out.append(
        f"states ({model.nstates}): " + (", ".join(f"{s} [{unit(s)}]" for s in model.states) or "none")
    )
    out.append(f"inputs ({model.ninputs}): " + (", ".join(model.inputs) or "none"))
    out.append(f"outputs ({model.noutputs}): " + (", ".join(model.outputs) or "none"))
    out.append(f"order of complexity: {model.info.order}")
    for excess in model.info.excess:
        out.append(f"  note: {excess.describe()}")
    for shift in model.info.shifts:
        out.append(f"  note: {shift.describe()}")
    out.append("")
    big = max(model.nstates, model.noutputs, model.ninputs) > TEXT_MATRIX_LIMIT
    if big:
        for name, mat in (
            ("A", model.A_sparse),
            ("B", model.B_sparse),
            ("C", model.C_sparse),
            ("D", model.D_sparse),
        ):
            out.append(
                f"{name}: {mat.shape[0]}x{mat.shape[1]}, {mat.nnz} non-zeros "
                "(use --format json for the entries)"
            )
    else:
        out += format_matrix("A", model.A, model.states, model.states)
        out += format_matrix("B", model.B, model.states, model.inputs)
        out += format_matrix("C", model.C, model.outputs, model.states)
        out += format_matrix("D", model.D, model.outputs, model.inputs)
        if model.has_input_derivative:
            out += format_matrix("D1 (multiplies du/dt)", model.D1, model.outputs, model.inputs)
    if eig is not None:
        out.append("")
        out.append(f"eigenvalues ({eig.method}):")
        out.append(
            f"  {'real [1/s]':>14} {'imag [1/s]':>14} {'wn [rad/s]':>12} {'fn':>11} {'damping':>9} "
            f"{'tau':>11} {'rel.err':>8}"
        )
        for m in eig.modes:
            tau = eng(m.time_constant, "s") if math.isfinite(m.time_constant) else "inf"
            zeta = f"{m.damping:.4g}" if math.isfinite(m.damping) else "-"
            if math.isfinite(m.rel_error):
                err = f"{m.rel_error:.0e}"
            elif math.isfinite(m.abs_error):
                err = f"±{m.abs_error:.0e}"  # λ = 0: only an absolute error makes sense
            else:
                err = "-"  # not estimated
            re, im = m.value.real + 0.0, m.value.imag + 0.0  # no "-0" in the table
            fn = eng(m.natural_frequency / (2 * math.pi), "Hz", 4)
            wn = m.natural_frequency
            out.append(f"  {re:>14.8g} {im:>14.8g} {wn:>12.6g} {fn:>11} {zeta:>9} {tau:>11} {err:>8}")
        stiff = f"{eig.stiffness_ratio:.4g}" if eig.stiffness_ratio is not None else "n/a"
        out.append(f"stability: {eig.verdict}; stiffness ratio: {stiff}")
        for warning in eig.warnings:
            out.append(f"warning: {warning}")
    return "\n".join(out) + "\n"


def validation_dict(report: Any, title: str, reference_accuracy: float | None = None) -> dict[str, Any]:
    """The JSON document for ``validate --format json``.

    ``outputs`` is the list of output names, as in ``analyze`` and
    ``simulate``; ``comparisons`` holds one record per output, in that order.
    """
    spice = report.spice
    doc: dict[str, Any] = {
        "netlist": report.netlist,
        "title": title,
        "passed": report.passed,
        "rtol": report.rtol,
        "horizon": {
            "tstep": report.horizon.tstep,
            "tstop": report.horizon.tstop,
            "source": report.horizon.source,
        },
        "ngspice": {
            "ok": spice.ok,
            "message": spice.message,
            "settings": spice.settings.describe(),
            "seconds": spice.seconds,
            "points": int(report.time.size),
            **({} if reference_accuracy is None else {"phase_error_bound": reference_accuracy}),
        },
        "model_seconds": report.model_seconds,
        "outputs": [c.name for c in report.comparisons],
        "comparisons": [
            {
                "name": c.name,
                "peak": c.peak,
                "max_abs_error": c.max_abs_error,
                "max_rel_error": c.max_rel_error,
                "rms_error": c.rms_error,
                "passed": c.max_rel_error <= report.rtol,
            }
            for c in report.comparisons
        ],
        "notes": list(report.notes),
    }
    original = getattr(report, "original", None)
    if original is not None:
        doc["original_file"] = {
            "ran": original.ran,
            "passed": original.passed,
            "worst_rel_difference": original.worst,
            "compared": original.compared,
            "message": original.message,
        }
    if report.poles is not None:
        poles = report.poles
        doc["poles"] = {
            "ngspice": [[p.real, p.imag] for p in poles.poles],
            "eigenvalues": [[p.real, p.imag] for p in poles.eigenvalues],
            "max_rel_difference": poles.max_rel_difference,
            "message": poles.message,
        }
    return doc


def validation_text(report: Any, title: str) -> str:
    """The human-readable ``validate`` report."""
    spice = report.spice
    hz = report.horizon
    out = [
        title,
        f"netlist: {report.netlist}",
        f"horizon: {eng(hz.tstop, 's')}, output step {eng(hz.tstep, 's')} ({hz.source})",
        f"ngspice: {spice.settings.describe()}",
    ]
    if not spice.ok:
        out.append(f"ngspice FAILED: {spice.message}")
    else:
        out.append(
            f"ngspice ran in {spice.seconds:.3f} s ({report.time.size} time points); "
            + (
                f"model (nonlinear transient at those points) in {report.model_seconds:.3f} s"
                if any("nonlinear transient" in n for n in report.notes)
                else f"model (exact first-order hold at those points) in {report.model_seconds:.3f} s"
            )
        )
        out.append("")
        width = max(8, *(len(c.name) for c in report.comparisons)) if report.comparisons else 8
        out.append(
            f"  {'output':<{width}} {'peak':>11} {'max |err|':>11} {'max err/peak':>13} "
            f"{'rms err':>11}  result"
        )
        for c in report.comparisons:
            verdict = "ok" if c.max_rel_error <= report.rtol else "MISMATCH"
            out.append(
                f"  {c.name:<{width}} {c.peak:>11.4g} {c.max_abs_error:>11.3g} {c.max_rel_error:>13.3g} "
                f"{c.rms_error:>11.3g}  {verdict}"
            )
    if report.poles is not None:
        poles = report.poles
        out.append("")
        if math.isfinite(poles.max_rel_difference):
            out.append(
                f"ngspice .pz: {len(poles.poles)} poles for {len(poles.eigenvalues)} eigenvalues; "
                f"each pole within {poles.max_rel_difference:.2g} (relative) of an eigenvalue"
                + (f" ({poles.message})" if poles.message else "")
                + " [informative]"
            )
        else:
            out.append(f"ngspice .pz: {poles.message} [informative]")
    for note in report.notes:
        out.append(f"note: {note}")
    out.append("")
    if report.passed:
        out.append(f"PASS: every output within {report.rtol:g} of its peak")
    elif not spice.ok:
        out.append(
            "INCONCLUSIVE: ngspice failed on this file (see the note): there is no reference to compare with"
        )
    else:
        bad = [c.name for c in report.comparisons if c.max_rel_error > report.rtol]
        if bad:
            out.append(f"FAIL: {', '.join(bad)} differ by more than {report.rtol:g} of their peak")
        original = getattr(report, "original", None)
        if original is not None and not original.passed:
            out.append("FAIL: the model disagrees with ngspice's reading of the original file (see the note)")
    return "\n".join(out) + "\n"


def simulation_csv(sim: Any) -> str:
    """Time and outputs as CSV with a header row (full double precision)."""
    header = ",".join(["time", *sim.outputs])
    rows = [",".join(repr(float(v)) for v in (t, *row)) for t, row in zip(sim.time, sim.values, strict=True)]
    return header + "\n" + "\n".join(rows) + "\n"


def simulation_dict(sim: Any, netlist: str | None = None) -> dict[str, Any]:
    """The JSON document for ``simulate --format json``.

    ``outputs`` is the list of output names, as in ``analyze`` and
    ``validate``; the samples are ``values[name]`` at ``time``.
    """
    doc: dict[str, Any] = {"netlist": netlist, "title": sim.title} if netlist else {"title": sim.title}
    doc.update(
        {
            "outputs": list(sim.outputs),
            "units": list(sim.units),
            "time": sim.time.tolist(),
            "values": {name: sim.values[:, j].tolist() for j, name in enumerate(sim.outputs)},
            "method": sim.method,
            "setting": sim.setting,
            "seconds": sim.seconds,
            "status": sim.status,
            "start": getattr(sim, "start", ""),
            "stats": dict(sim.stats),
            "horizon": {"tstep": sim.horizon.tstep, "tstop": sim.horizon.tstop, "source": sim.horizon.source},
        }
    )
    return doc


def simulation_summary(sim: Any) -> str:
    """Per output: value at the end, minimum and maximum (the samples go to --csv or JSON)."""
    rows = simulation_rows(sim)
    width = max(8, *(len(r[0]) for r in rows)) if rows else 8
    lines = [f"  {'output':<{width}} {'final':>14} {'min':>14} {'max':>14}"]
    lines += [f"  {name:<{width}} {final:>14} {low:>14} {high:>14}" for name, final, low, high in rows]
    lines.append("(the samples: --csv FILE or --format json)")
    return "\n".join(lines) + "\n"


def bench_head_dict(report: Any) -> dict[str, Any]:
    """The part of ``bench --format json`` known once the reference is: everything but the rows."""
    return {
        "netlist": report.netlist,
        "title": report.title,
        "nstates": report.nstates,
        "horizon": {"tstop": report.horizon.tstop, "points": report.points},
        "reference": {
            "method": report.reference.method,
            "check": report.reference.check,
            "agreement": report.reference.agreement,
            "seconds": report.reference.seconds,
        },
        "budget": report.budget,
    }


def bench_row_dict(row: Any) -> dict[str, Any]:
    """One row of ``bench --format json`` (wall and CPU seconds, runs behind the median)."""
    return {
        "method": row.method,
        "setting": row.setting,
        "error": row.error,
        "seconds": row.seconds,
        "cpu_seconds": row.cpu,
        "runs": row.runs,
        "status": row.status,
        "message": row.message,
    }


def bench_dict(report: Any) -> dict[str, Any]:
    """The JSON document for ``bench --format json``."""
    return {
        **bench_head_dict(report),
        "elapsed": report.elapsed,
        "load_average": _load_average(),
        "rows": [bench_row_dict(r) for r in report.rows],
    }


def _load_average() -> float | None:
    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return None


BENCH_COLUMNS = f"  {'method':<14} {'setting':<44} {'error/peak':>11} {'wall s':>9} {'CPU s':>9}  status"


def bench_text_head(report: Any) -> str:
    """The ``bench`` report's head: the case, the reference and its accuracy, the column titles."""
    ref = report.reference
    budget = f"; budget {report.budget:g} CPU s" if math.isfinite(report.budget) else ""
    took = f" ({ref.seconds:.3g} s)" if math.isfinite(ref.seconds) else ""
    return (
        "\n".join(
            [
                report.title,
                f"netlist: {report.netlist}; {report.nstates} states; "
                f"horizon {eng(report.horizon.tstop, 's')}, scored at {report.points} grid steps{budget}",
                f"reference: {ref.method}{took}; accuracy {ref.agreement:.2g}: "
                f"its agreement with {ref.check}",
                "",
                BENCH_COLUMNS,
            ]
        )
        + "\n"
    )


def bench_text_row(row: Any) -> str:
    """One line of the ``bench`` table."""
    err = f"{row.error:.2g}" if math.isfinite(row.error) else "-"
    sec = f"{row.seconds:.3f}" if math.isfinite(row.seconds) and row.status != "stopped" else "-"
    cpu = f"{row.cpu:.3f}" if math.isfinite(row.cpu) else "-"
    if row.status == "ok":
        note = "ok" if row.runs <= 1 else f"ok (median of {row.runs})"
        note += f"; {row.message}" if row.message else ""
    else:
        note = row.message if row.status == "stopped" else f"{row.status}: {row.message}"
    return f"  {row.method:<14} {row.setting:<44} {err:>11} {sec:>9} {cpu:>9}  {note}\n"


def bench_text_tail(report: Any) -> str:
    """The ``bench`` report's last line: time taken against the budget, rows stopped or skipped, load."""
    counts = {s: sum(r.status == s for r in report.rows) for s in ("stopped", "skipped")}
    budget = f" of the {report.budget:g} CPU s budget" if math.isfinite(report.budget) else ""
    load = _load_average()
    where = f"; load average {load:.2g} on {os.cpu_count()} CPUs" if load is not None else ""
    return (
        f"done in {report.elapsed:.3g} CPU s{budget}; {len(report.rows)} rows, {counts['stopped']} stopped, "
        f"{counts['skipped']} skipped{where}\n"
    )


def bench_line(record: dict[str, Any]) -> str:
    """One record of ``bench --format json --stream`` as one line of JSON."""
    return json.dumps(_clean(record))


def bench_text(report: Any) -> str:
    """The ``bench`` table for people."""
    return bench_text_head(report) + "".join(bench_text_row(r) for r in report.rows) + bench_text_tail(report)


def control_dict(structure: Any, tfs: Sequence[Any]) -> dict[str, Any]:
    """JSON for ``analyze --control``."""
    return {
        "controllable": structure.controllable,
        "observable": structure.observable,
        "uncontrollable_modes": [[v.real, v.imag] for v in structure.uncontrollable],
        "unobservable_modes": [[v.real, v.imag] for v in structure.unobservable],
        "controllable_dimension": structure.ranks[0],
        "observable_dimension": structure.ranks[1],
        "rank_tolerance": structure.tolerance,
        "decision_margin": structure.margin,
        "transfer_functions": [
            {
                "output": t.output,
                "input": t.input,
                "num": list(t.num),
                "den": list(t.den),
                "poles": [[p.real, p.imag] for p in t.poles],
                "zeros": [[z.real, z.imag] for z in t.zeros],
                "dc_gain": t.dc_gain,
            }
            for t in tfs
        ],
    }


def control_text(structure: Any, tfs: Sequence[Any]) -> str:
    """Text for ``analyze --control``."""

    def modes(values: Sequence[complex]) -> str:
        return ", ".join(f"{v:.6g}" for v in values)

    out = [
        "",
        "controllability (PBH on the equilibrated Hautus matrices, cosine tolerance "
        f"{structure.tolerance:g}): "
        + (
            "controllable"
            if structure.controllable
            else f"uncontrollable modes {modes(structure.uncontrollable)}"
        ),
        "observability (PBH): "
        + ("observable" if structure.observable else f"unobservable modes {modes(structure.unobservable)}"),
    ]
    if structure.margin < 1e3:
        out.append(
            f"note: the closest decision passed its tolerance by a factor of only {structure.margin:.3g}: "
            "a mode is nearly uncontrollable or nearly unobservable"
        )
    for t in tfs:
        out.append(t.text())
        if t.cancelled > 0:
            reduced = t.minimal().text().split(" = ", 1)[1]
            out.append(
                f"  = {reduced}  ({t.cancelled} common factor(s) cancelled: modes this pair does not see)"
            )
        out.append(f"  DC gain {t.dc_gain:.6g}; poles {modes(t.poles) or '-'}; zeros {modes(t.zeros) or '-'}")
    return "\n".join(out) + "\n"


def sweep_record_json(record: dict[str, Any]) -> str:
    """One sweep case as one line of JSON (``sweep --format jsonl``), full precision."""
    return json.dumps(_clean(record))


#: Sweeps with more modes than this list them under each case instead of in columns.
SWEEP_COLUMN_MODES = 6


def _eigenvalue(re: float, im: float) -> str:
    re, im = re + 0.0, im + 0.0  # no "-0"
    return f"{re:.8g}" + (f"{'-' if im < 0 else '+'}{abs(im):.8g}j" if im else "")


def mode_figures(re: float, im: float) -> tuple[float, float]:
    """Natural frequency (Hz) and damping ratio of the eigenvalue ``re + j im`` (1/s).

    fn = |λ|/2π and ζ = −Re λ/|λ|; a zero eigenvalue has fn = 0 and ζ = NaN (no rate to compare with).
    """
    magnitude = math.hypot(re, im)
    return magnitude / (2 * math.pi), (-re / magnitude if magnitude > 0 else math.nan)


def _mode_cells(re: float, im: float) -> list[str]:
    fn, zeta = mode_figures(re, im)
    return [_eigenvalue(re, im), eng(fn, "Hz", 4), "-" if math.isnan(zeta) else f"{zeta:.4g}"]


def sweep_text(cases: Sequence[dict[str, Any]]) -> str:
    """A table of eigenvalues per case: parameters in the user's spelling, modes in tracked order.

    Column λk follows one mode from case to case (see
    :func:`netlistdyn.workflows.sweep.track`); values in 1/s, with the mode's natural frequency
    fnk (Hz) and damping ratio ζk beside it. Sweeps of more than :data:`SWEEP_COLUMN_MODES` modes
    list the eigenvalues under each case.
    """
    names = list(cases[0]["params"]) if cases else []
    modes = max((len(c.get("eigenvalues", ())) for c in cases), default=0)
    columns = modes <= SWEEP_COLUMN_MODES
    per_mode = ("λ{} [1/s]", "fn{}", "ζ{}")
    head = [
        "case",
        *names,
        "stability",
        *(h.format(k + 1) for k in range(modes if columns else 0) for h in per_mode),
    ]
    table: list[list[str]] = []
    below: dict[int, str] = {}
    for number, case in enumerate(cases):
        cells = [str(case.get("index", number) + 1), *(eng(case["params"][k], "", 6) for k in names)]
        if "error" in case:
            below[len(table)] = f"error: {case['error']}"
            table.append(cells)
            continue
        values = [_eigenvalue(re, im) for re, im in case["eigenvalues"]]
        figures = [cell for re, im in case["eigenvalues"] for cell in _mode_cells(re, im)]
        table.append([*cells, case["stability"], *(figures if columns else [])])
        if not columns:
            below[len(table) - 1] = "eigenvalues: " + ", ".join(values)
    widths = [max(len(h), *(len(r[k]) for r in table if len(r) > k)) for k, h in enumerate(head)]
    numeric = 1 + len(names)  # case and parameter columns align right

    def line(cells: Sequence[str]) -> str:
        parts = [
            c.rjust(w) if k < numeric else c.ljust(w)
            for k, (c, w) in enumerate(zip(cells, widths, strict=False))
        ]
        return "  ".join(parts).rstrip()

    out = [line(head)]
    for k, row in enumerate(table):
        if k in below and len(row) == numeric:
            out.append(line(row) + "  " + below[k])
            continue
        out.append(line(row))
        if k in below:
            out.append("      " + below[k])
    return "\n".join(out) + "\n"


def symbolic_dict(model: Any) -> dict[str, Any]:
    """JSON for ``analyze --symbolic``: entries as sympy strings (``sympy.sympify`` reads them)."""
    from netlistdyn.formulation.symbolic import entry_strings, json_names  # noqa: PLC0415 (deferred, imports sympy: optional symbolic extra)

    names = json_names(list(model.symbols))
    doc: dict[str, Any] = {
        "symbols": {names[name]: value for name, (_, value) in model.symbols.items()},
    }
    doc["symbol_units"] = {names[name]: model.units.get(name, "") for name in model.symbols}
    renamed = {names[name]: name for name in model.symbols if names[name] != name}
    if renamed:  # E, I, pi, X1.R1 … would not read back as symbols
        doc["symbol_elements"] = renamed
    for key in ("A", "B", "C", "D"):
        doc[key] = entry_strings(getattr(model, key), names)
    if not model.D1.is_zero_matrix:
        doc["D1"] = entry_strings(model.D1, names)
    return doc


def symbolic_text(model: Any) -> str:
    """The non-zero symbolic entries of each matrix, labelled by state, input and output."""
    import sympy  # noqa: PLC0415 (deferred, sympy: optional symbolic extra)

    symbols = ", ".join(
        element_value(name, value, model.units.get(name, "")) for name, (_, value) in model.symbols.items()
    )
    out = ["", f"symbolic model (sympy; netlist values: {symbols or 'none, all substituted'})"]
    labels = {
        "A": (model.states, model.states),
        "B": (model.states, model.inputs),
        "C": (model.outputs, model.states),
        "D": (model.outputs, model.inputs),
        "D1": (model.outputs, model.inputs),
    }
    for key, (rows, cols) in labels.items():
        matrix = getattr(model, key)
        if key == "D1" and matrix.is_zero_matrix:
            continue
        entries = [
            f"  {key}[{rows[i]}, {cols[j]}] = {sympy.sstr(matrix[i, j])}"
            for i in range(matrix.rows)
            for j in range(matrix.cols)
            if matrix[i, j] != 0
        ]
        out.append(f"{key} ({matrix.rows}x{matrix.cols}), non-zero entries:" if entries else f"{key} = 0")
        out.extend(entries)
    return "\n".join(out) + "\n"


#: The canonical forms of ``analyze --canonical``, in order (JSON keys).
CANONICAL_KINDS = ("controller", "observer", "observer_all_outputs")


def canonical_forms(model: StateSpaceModel) -> list[Any]:
    """Controller, observer (one output) and observer (all outputs) forms, or why each is unavailable."""
    out: list[Any] = []
    for build in (control.controller_form, control.observer_form, control.observer_form_multi):
        try:
            out.append(build(model))
        except UsageError as exc:
            out.append(str(exc))
    return out


def canonical_dict(forms: Sequence[Any]) -> dict[str, Any]:
    """JSON for ``analyze --canonical``."""
    doc: dict[str, Any] = {}
    for kind, form in zip(CANONICAL_KINDS, forms, strict=True):
        if isinstance(form, str):
            doc[kind] = {"unavailable": form}
            continue
        doc[kind] = {
            "signal": form.signal,
            "T": form.T.tolist(),
            "A": form.A.tolist(),
            "B": form.B.tolist(),
            "C": form.C.tolist(),
            "condition_T": form.condition,
            "pattern_residual": form.residual,
        }
    return doc


def canonical_text(model: StateSpaceModel, forms: Sequence[Any]) -> str:
    """The companion forms with their transformation's condition number."""
    out: list[str] = []
    for kind, form in zip(CANONICAL_KINDS, forms, strict=True):
        out.append("")
        title = kind.replace("_", " ").replace("all outputs", "(all outputs)")
        if isinstance(form, str):
            out.append(f"{title} form: unavailable ({form})")
            continue
        via = "input " if kind == "controller" else ("output " if kind == "observer" else "")
        out.append(
            f"{title} form (x̃ = T x, from {via}{form.signal}; cond(T) = {form.condition:.3g}, "
            f"companion pattern residual {form.residual:.2g}):"
        )
        labels = [f"x̃{k + 1}" for k in range(model.nstates)]
        out += format_matrix("Ã" if kind == "controller" else "Â", form.A, labels, labels)
        out += format_matrix("B̃" if kind == "controller" else "B̂", form.B, labels, model.inputs)
        out += format_matrix("C̃" if kind == "controller" else "Ĉ", form.C, model.outputs, labels)
    return "\n".join(out) + "\n"
