"""Write the faulty inputs of tests/bad_inputs/ and their manifest (run from anywhere).

Each case is one file in this folder and one entry in ``manifest.json``:

- ``file``: the input; ``args``: the command line, with ``{file}`` for the input's path;
- ``exit``: the expected exit status (1 bad netlist, 2 bad command line or model file);
- ``where``: what the one stderr line starts with or names — ``"{file}:N"`` for a netlist line,
  else an option (``"--tstop"``) or the file name;
- ``fragment``: a piece of the message;
- ``setup`` (optional): ``"fifo"`` makes the named extra path a FIFO before the run;
- ``isolate`` (optional): run in a child process with a memory limit (inputs that, unfixed,
  grow without bound or block);
- ``owner`` (optional): the helper whose fix the case waits for (the test marks it xfail,
  non-strict, naming them).

``python tests/bad_inputs/make_inputs.py`` rewrites everything; the files are committed, so a
reader sees exactly what is tested.
"""

from __future__ import annotations

import json
import struct
import zipfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
GOOD = (
    "Circuit 1 of the lecture notes\n"
    ".param R1=1m R2=1m L1=1 C1=1\n"
    "Vin in 0 DC 1\n"
    "R1 in a {R1}\n"
    "C1 a 0 {C1}\n"
    "R2 a 0 {R2}\n"
    "L1 a 0 {L1}\n"
    ".tran 1m 10\n"
)
TITLE = "bad input\n"
CASES: list[dict[str, Any]] = []


def _add(file: str, args: list[str], code: int, where: str, fragment: str, **extra: Any) -> None:
    """One case: the input ``file`` (given by ``text`` or ``bytes`` in ``extra``), its command line
    and the exit status, stderr prefix and message fragment it must produce; a None extra is left out."""
    case = {"file": file, "args": args, "exit": code, "where": where, "fragment": fragment}
    CASES.append({**case, **{k: v for k, v in extra.items() if v is not None}})


def netlist(
    name: str, body: str, line: int, fragment: str, owner: str | None = None, args: list[str] | None = None
) -> None:
    """A netlist whose line ``line`` (1 = title) is wrong; analyze (or ``args``) exits 1."""
    args = args or ["analyze", "{file}"]
    _add(f"{name}.cir", args, 1, f"{{file}}:{line}", fragment, text=TITLE + body, owner=owner)


def option(name: str, args: list[str], fragment: str, where: str, owner: str | None = None) -> None:
    """A good netlist with a bad command line; exit 2 naming the option ``where``."""
    _add(f"opt_{name}.cir", args, 2, where, fragment, text=GOOD, owner=owner)


def raw(name: str, data: bytes, args: list[str], code: int, where: str, fragment: str, **extra: Any) -> None:
    """An input given as bytes (binary files, saved models)."""
    _add(name, args, code, where, fragment, bytes=data, **extra)


# --- netlists: syntax and values -----------------------------------------------------------
V = "V1 a 0 1\n"
netlist("voltage_loop", "V1 a 0 1\nV2 a 0 2\nR1 a 0 1\n", 3, "loop of voltage sources")
netlist("shorted_source", "V1 a a 1\nR1 a 0 1\n", 2, "short-circuited")
netlist("current_cutset", "I1 0 a 1\nI2 a b 1\nR1 b 0 1\n", 2, "cutset of current sources")
netlist("zero_resistor", V + "R1 a 0 0\n", 3, "zero")
netlist("zero_capacitor", V + "R1 a b 1\nC1 b 0 0\n", 4, "zero")
netlist("zero_inductor", V + "R1 a b 1\nL1 b 0 0\n", 4, "zero")
netlist("infinite_value", V + "R1 a 0 1e999\n", 3, "not finite")
netlist("division_by_zero", V + "R1 a 0 {1/0}\n", 3, "division by zero")
netlist("floating_node", V + "R1 a 0 1\nC1 b c 1u\n", 4, "no path to ground")
netlist("unknown_sense_source", V + "R1 a 0 1\nF1 a 0 Vx 2\n", 4, "not a voltage source")
netlist("unknown_coupled_inductor", V + "L1 a 0 1\nK1 L1 L9 0.5\n", 4, "not an inductor")
netlist("unknown_control_node", V + "R1 a 0 1\nE1 b 0 zz 0 2\nR2 b 0 1\n", 4, "'zz'")
netlist("diode", V + "D1 a 0 dmod\n", 3, "no .model dmod")
netlist("unknown_letter", V + "YQ1 a 0 1\n", 3, "YQ1")
netlist("lib_directive", V + "R1 a 0 1\n.lib foo\n", 4, ".lib")
netlist("unknown_parameter", V + "R1 a 0 {rx*2}\n", 3, "unknown parameter 'rx'")
netlist("missing_value", V + "R1 a 0\n", 3, "missing resistance")
netlist("extra_field", V + "R1 a 0 1k 2k\n", 3, "R1")
netlist("duplicate_name", V + "R1 a 0 1\nr1 a 0 2\n", 4, "duplicate")
netlist("perfect_coupling", V + "L1 a 0 1\nL2 a 0 1\nK1 L1 L2 1\n", 5, "ideal transformer")
netlist("coupling_above_one", V + "R1 a b 1\nL1 b 0 1\nL2 b 0 1\nK1 L1 L2 1.5\n", 6, "K1")
netlist("nonlinear_source", V + "R1 a 0 1\nE1 b 0 VALUE={v(a)*v(zz)}\n", 4, "v(zz) names no node")
netlist("poly_without_coefficients", V + "R1 a 0 1\nE1 b 0 POLY(1) a 0\nR2 b 0 1\n", 4, "POLY(1) needs")
netlist("poly_fractional_dimension", V + "R1 a 0 1\nG1 b 0 POLY(1.5) a 0 0 1\nR2 b 0 1\n", 4, "whole number")
netlist("leading_continuation", "+ R1 a 0 1\n", 2, "continuation")
netlist("pwl_odd", "V1 a 0 PWL(0 0 1)\nR1 a 0 1\n", 2, "PWL")
netlist("pwl_time_backwards", "V1 a 0 PWL(0 0 2 1 1 0)\nR1 a 0 1\n", 2, "V1")
netlist("pulse_too_many", "V1 a 0 PULSE(0 1 0 1 1 1 1 1 1)\nR1 a 0 1\n", 2, "PULSE")
netlist("sin_too_few", "V1 a 0 SIN(0)\nR1 a 0 1\n", 2, "SIN")
netlist("exp_too_many", "V1 a 0 EXP(0 1 0 1 1 1 1)\nR1 a 0 1\n", 2, "EXP")
netlist("unknown_waveform", "V1 a 0 TRIANGLE(0 1)\nR1 a 0 1\n", 2, "V1")
netlist("unclosed_waveform", "V1 a 0 PULSE(0 1 0 1m\nR1 a 0 1\n", 2, "V1")
netlist("pulse_negative_period", "V1 a 0 PULSE(0 1 0 1u 1u 1m -1)\nR1 a 0 1\n", 2, "period")
netlist("tran_negative", V + "R1 a 0 1\n.tran -1m 1\n", 4, ".tran")
netlist("tran_not_number", V + "R1 a 0 1\n.tran 1m abc\n", 4, ".tran")
netlist("param_no_value", ".param x\n" + V + "R1 a 0 1\n", 2, ".param")
netlist("param_loop", ".param x={y} y={x}\n" + V + "R1 a 0 {x}\n", 2, "x")
netlist("param_bad_expression", ".param x={1+}\n" + V + "R1 a 0 {x}\n", 2, "x")
netlist("unbalanced_brace", V + "R1 a 0 {1+2\n", 3, "R1")
netlist("unknown_function", V + "R1 a 0 {frobnicate(2)}\n", 3, "frobnicate")
netlist("sqrt_negative", V + "R1 a 0 {sqrt(-1)}\n", 3, "R1")
netlist("log_base_one", V + "R1 a 0 {log(2,1)}\n", 3, "R1")
netlist("value_5000_digits", V + "R1 a 0 " + "9" * 5000 + "\n", 3, "R1")
netlist("exponent_5000_digits", V + "R1 a 0 1e" + "9" * 5000 + "\n", 3, "R1")
netlist("expression_5000_digits", V + "R1 a 0 {" + "9" * 5000 + "*2}\n", 3, "R1")
netlist("power_overflow", V + "R1 a 0 {10**400}\n", 3, "R1")
CASES[-1]["isolate"] = True
netlist("nan_value", V + "R1 a 0 nan\n", 3, "R1")
netlist("inf_value", V + "R1 a 0 inf\n", 3, "R1")
netlist("empty_expression", V + "R1 a 0 {}\n", 3, "R1")
netlist("only_delimiters", V + "R1 a 0 1\n(\n", 4, "(")
netlist("current_source_no_nodes", "V1 a 0 1\nR1 a 0 1\nI1 a\n", 4, "I1")
netlist("vcvs_missing_gain", V + "R1 a 0 1\nE1 b 0 a 0\nR2 b 0 1\n", 4, "E1")
netlist("vccs_missing_nodes", V + "R1 a 0 1\nG1 b 0 a\nR2 b 0 1\n", 4, "G1")
netlist("cccs_missing_source", V + "R1 a 0 1\nF1 b 0\nR2 b 0 1\n", 4, "F1")
netlist("ccvs_sense_is_resistor", V + "R1 a 0 1\nH1 b 0 R1 2\nR2 b 0 1\n", 4, "H1")
netlist("coupling_missing_value", V + "R1 a b 1\nL1 b 0 1\nL2 b 0 1\nK1 L1 L2\n", 6, "K1")
netlist("coupling_same_inductor", V + "R1 a b 1\nL1 b 0 1\nK1 L1 L1 0.5\n", 5, "K1")
netlist("element_name_only", V + "R1\n", 3, "R1")
netlist("capacitor_source_loop_only", "V1 a 0 1\nC1 a 0 1u\nR1 a 0 {-1/0}\n", 4, "R1")
netlist("no_elements", "* nothing but a comment\n", 1, "no element")
netlist("subckt_undefined", V + "R1 a 0 1\nX1 a 0 nothere\n", 4, "nothere")
netlist("subckt_wrong_ports", ".subckt half p n\nR1 p n 1\n.ends\n" + V + "X1 a half\nR2 a 0 1\n", 6, "X1")
netlist("subckt_missing_ends", ".subckt half p n\nR1 p n 1\n" + V, 2, ".subckt")
netlist("subckt_stray_ends", V + "R1 a 0 1\n.ends\n", 4, ".ends")
netlist(
    "subckt_self_instance",
    ".subckt loop p n\nX1 p n loop\n.ends\n" + V + "X9 a 0 loop\nR1 a 0 1\n",
    3,
    "instantiates itself",
)
netlist("subckt_no_name", ".subckt\n.ends\n" + V + "R1 a 0 1\n", 2, ".subckt")
netlist("include_missing", V + "R1 a 0 1\n.include nothere.cir\n", 4, "nothere.cir")
netlist("include_no_name", V + "R1 a 0 1\n.include\n", 4, ".include")
netlist("include_loop", V + "R1 a 0 1\n.include include_loop.cir\n", 4, "include loop")
netlist("include_binary", V + "R1 a 0 1\n.include binary.bin\n", 4, "binary.bin")
netlist("include_fifo", V + "R1 a 0 1\n.include fifo.inc\n", 4, "fifo.inc")
CASES[-1]["setup"] = "fifo"
CASES[-1]["extra"] = "fifo.inc"
CASES[-1]["isolate"] = True
netlist("include_directory", V + "R1 a 0 1\n.include .\n", 4, ".include")

# Mechanical keywords.
M = "FORCE f1 a 0 1\n"
netlist("mass_no_value", M + "MASS m1 a\n", 3, "m1")
netlist("mass_zero", M + "MASS m1 a 0\n", 3, "m1")
netlist("spring_one_node", M + "MASS m1 a 1\nSPRING k1 a\n", 4, "k1")
netlist("damper_extra_field", M + "MASS m1 a 1\nDAMPER d1 a 0 1 2\n", 4, "d1")
netlist("rod_no_mass", "FORCE f1 b 0 1\nROD r1 0 b 1\nSPRING k1 b 0 1\n", 3, "carries no weight")
netlist("rod_cycle", "FORCE f1 a 0 1\nROD r1 a b 1\nROD r2 b a 1\nMASS m1 a 1\n", 3, "cycle")
netlist("rod_negative_length", M + "MASS m1 a 1\nROD r1 0 a -1\n", 4, "length")
netlist("rod_zero_g", M + "MASS m1 a 1\nROD r1 0 a 1 g=0\n", 4, "g")
netlist("rod_g_no_value", M + "MASS m1 a 1\nROD r1 0 a 1 g=\n", 4, "g")
netlist("gear_missing_ratio", M + "INERTIA j1 a 1\nINERTIA j2 b 1\nGEAR g1 a b\n", 5, "g1")
netlist("motor_missing_field", M + "INERTIA j1 a 1\nMOTOR mo1 a 0\n", 4, "mo1")
netlist("mass_missing_name", M + "MASS\n", 3, "MASS")
netlist("velocity_loop", "VELOCITY v1 a 0 1\nVELOCITY v2 a 0 2\nDAMPER d1 a 0 1\n", 3, "v2")
netlist("force_cutset", "FORCE f1 0 a 1\nFORCE f2 a b 1\nDAMPER d1 b 0 1\n", 2, "cutset")

# Expansion and breakpoint bombs (refused with a limit).
bomb = []
for level in range(9):
    inner = f"s{level - 1}" if level else None
    bomb.append(f".subckt s{level} p n")
    bomb += [f"X{k} p n {inner}" for k in range(10)] if inner else ["R1 p n 1"]
    bomb.append(".ends")
netlist("subckt_bomb", "\n".join(bomb) + "\n" + V + "X1 a 0 s8\n", 1 + len(bomb) + 2, "X1")
CASES[-1]["isolate"] = True
# Transients that cannot run: refused before any time stepping (by simulate and by validate).
PULSE_1PS = "V1 a 0 PULSE(0 1 0 0.1p 0.1p 0.4p 1p)\nR1 a b 1\nC1 b 0 1u\n.tran 1m 1\n"
for command, suffix in (("simulate", ""), ("validate", "_validate")):
    netlist(f"pulse_1ps_period{suffix}", PULSE_1PS, 2, "breakpoints", args=[command, "{file}"])
    CASES[-1]["isolate"] = True
TRNOISE = "V1 a 0 DC 0 TRNOISE(1n 1n 0 0)\nR1 a b 1k\nC1 b 0 1u\n.tran 1u 1m\n"
netlist("trnoise_simulate", TRNOISE, 2, "random waveform", args=["simulate", "{file}"])

# Top-level files that are not netlists.
raw("binary_top.cir", bytes(range(256)) * 4, ["analyze", "{file}"], 1, "{file}", "not a text file")
raw(
    "nul_bytes.cir",
    b"title\nV1 a 0 1\x00\nR1 a 0 1\n",
    ["analyze", "{file}"],
    1,
    "{file}",
    "not a text file",
)
raw("empty.cir", b"", ["analyze", "{file}"], 1, "{file}", "no element")
raw(
    "dev_zero.txt",
    b"analyze /dev/zero reads this path instead\n",
    ["analyze", "/dev/zero"],
    1,
    "/dev/zero",
    "not a regular file",
)
CASES[-1]["isolate"] = True

# --- command-line options -----------------------------------------------------------------
F = "{file}"
BIG = "9" * 5000
option("format_xml", ["analyze", F, "--format", "xml"], "Invalid value", "--format")
option("eig_bogus", ["analyze", F, "--eig", "bogus"], "Invalid value", "--eig")
option("method_bogus", ["simulate", F, "--method", "bogus"], "Invalid value", "--method")
option("output_no_node", ["analyze", F, "--output", "v(nowhere)"], "no node 'nowhere'", "--output")
option("output_no_element", ["analyze", F, "--output", "i(R9)"], "no element 'R9'", "--output")
option("output_garbage", ["analyze", F, "--output", "x"], "expected v(node)", "--output")
option("output_unclosed", ["analyze", F, "--output", "v(a"], "v(", "--output")
option("output_empty", ["analyze", F, "--output", ""], "output", "--output")
option("param_no_equals", ["analyze", F, "--param", "R1"], "expected NAME=VALUE", "--param")
option("param_unknown", ["analyze", F, "--param", "Rz=1"], "no .param rz", "--param")
option("param_not_number", ["analyze", F, "--param", "R1=abc"], "not a number", "--param")
option("param_inf", ["analyze", F, "--param", "R1=inf"], "not a", "--param")
option("param_nan", ["analyze", F, "--param", "R1=nan"], "not", "--param")
option("param_5000_digits", ["analyze", F, "--param", "R1=" + BIG], "not a number", "--param")
option("param_empty_name", ["analyze", F, "--param", "=1"], "expected NAME=VALUE", "--param")
option("ic_unknown_state", ["simulate", F, "--ic", "q(C9)=1"], "states: q(C1)", "--ic")
option("ic_nan", ["simulate", F, "--ic", "q(C1)=nan"], "finite number", "--ic")
option("ic_5000_digits", ["simulate", F, "--ic", "q(C1)=" + BIG], "finite number", "--ic")
option("ic_no_equals", ["simulate", F, "--ic", "q(C1)"], "expected NAME=VALUE", "--ic")
option("tstop_inf", ["simulate", F, "--tstop", "inf"], "not a", "--tstop")
option("tstop_nan", ["simulate", F, "--tstop", "nan"], "not", "--tstop")
option("tstop_zero", ["simulate", F, "--tstop", "0"], "positive", "--tstop")
option("tstop_negative", ["simulate", F, "--tstop", "-1"], "positive", "--tstop")
option("tstop_5000_digits", ["simulate", F, "--tstop", BIG], "not a", "--tstop")
option("tstop_word", ["simulate", F, "--tstop", "soon"], "not a number", "--tstop")
option("tstep_zero", ["simulate", F, "--tstep", "0"], "positive", "--tstep")
option("tstep_too_fine", ["simulate", F, "--tstop", "10", "--tstep", "1e-9"], "output points", "--tstep")
option("rtol_zero", ["simulate", F, "--rtol", "0"], "positive", "--rtol")
option("atol_negative", ["simulate", F, "--atol", "-1e-9"], "positive", "--atol")
option("validate_tstop_inf", ["validate", F, "--tstop", "inf"], "not a", "--tstop")
option("validate_timeout_zero", ["validate", F, "--timeout", "0"], "positive", "--timeout")
option("validate_rtol_nan", ["validate", F, "--rtol", "nan"], "not", "--rtol")
option("bench_points_zero", ["bench", F, "--points", "0"], "positive", "--points")
option("bench_points_huge", ["bench", F, "--points", "1e9"], "more than 1,000,000", "--points")
option("bench_points_5000_digits", ["bench", F, "--points", BIG], "--points", "--points")
option("bench_repeats_zero", ["bench", F, "--repeats", "0"], "--repeats", "--repeats")
option("bench_reference_rtol_inf", ["bench", F, "--reference-rtol", "inf"], "not a", "--reference-rtol")
option("bench_method_auto", ["bench", F, "--method", "auto"], "Invalid value", "--method")
option("sweep_count_superscript", ["sweep", F, "--param", "R1=lin:1:2:²"], "COUNT", "--param")
option("sweep_count_zero", ["sweep", F, "--param", "R1=lin:1:2:0"], "COUNT", "--param")
option("sweep_count_fraction", ["sweep", F, "--param", "R1=lin:1:2:1.5"], "COUNT", "--param")
option("sweep_count_word", ["sweep", F, "--param", "R1=lin:1:2:ten"], "COUNT", "--param")
option("sweep_count_1e10", ["sweep", F, "--param", "R1=lin:1:2:10000000000"], "--max-cases", "--param")
option("sweep_count_5000_digits", ["sweep", F, "--param", "R1=lin:1:2:" + BIG], "COUNT", "--param")
option("sweep_range_overflow", ["sweep", F, "--param", "R1=lin:1e400:1:5"], "not a finite number", "--param")
option("sweep_range_nan", ["sweep", F, "--param", "R1=lin:nan:1:5"], "not", "--param")
option("sweep_range_span_overflow", ["sweep", F, "--param", "R1=lin:-1e308:1e308:5"], "overflows", "--param")
option("sweep_log_negative", ["sweep", F, "--param", "R1=log:-1:10:5"], "positive ends", "--param")
option("sweep_log_parts", ["sweep", F, "--param", "R1=log:1:10"], "log:START:STOP:COUNT", "--param")
option("sweep_list_word", ["sweep", F, "--param", "R1=1,two,3"], "'two' is not a number", "--param")
option("sweep_list_empty_item", ["sweep", F, "--param", "R1=1,,3"], "not a number", "--param")
option("sweep_list_inf", ["sweep", F, "--param", "R1=1,inf"], "not a", "--param")
option("sweep_list_5000_digits", ["sweep", F, "--param", f"R1=1,{BIG}"], "not a number", "--param")
option("sweep_no_param", ["sweep", F], "sweep needs --param NAME=VALUES", "--param")
option("sweep_no_equals", ["sweep", F, "--param", "R1"], "expected NAME=VALUES", "--param")
option(
    "sweep_product_huge",
    ["sweep", F, "--param", "R1=lin:1:2:1000", "--param", "R2=lin:1:2:1000", "--param", "C1=1,2,3"],
    "3,000,000 cases",
    "--param",
)
option(
    "sweep_max_cases_zero", ["sweep", F, "--param", "R1=1", "--max-cases", "0"], "--max-cases", "--max-cases"
)
option("sweep_jobs_zero", ["sweep", F, "--param", "R1=1,2", "--jobs", "0"], "--jobs", "--jobs")
option("sweep_jobs_negative", ["sweep", F, "--param", "R1=1,2", "--jobs", "-3"], "--jobs", "--jobs")
option("sweep_jobs_5000_digits", ["sweep", F, "--param", "R1=1,2", "--jobs", BIG], "--jobs", "--jobs")
option(
    "sweep_scheduler_bogus",
    ["sweep", F, "--param", "R1=1,2", "--scheduler", "bogus"],
    "expected processes",
    "--scheduler",
)
option(
    "sweep_scheduler_no_port",
    ["sweep", F, "--param", "R1=1,2", "--scheduler", "tcp://host"],
    "tcp://HOST:PORT",
    "--scheduler",
)
option("sweep_unknown_param", ["sweep", F, "--param", "Rz=1,2"], "rz", "--param")
# "-" reads standard input (empty here): the same answer as an empty file.
option("sweep_stdin_empty", ["sweep", "-", "--param", "R1=1,2"], "defines no .param r1", "--param")
option("save_unknown_suffix", ["analyze", F, "--save", "model.xyz"], "unknown format", "--save")
option("save_no_folder", ["analyze", F, "--save", "nodir/model.npz"], "does not exist", "--save")
option("out_no_folder", ["analyze", F, "--save", "model.npz", "-o", "nodir/out.txt"], "does not exist", "-o")
option("out_is_directory", ["analyze", F, "-o", "."], "directory", "-o")
option("out_same_as_save", ["analyze", F, "--save", "m.json", "-o", "m.json"], "both write", "-o")
option("csv_no_folder", ["simulate", F, "--csv", "nodir/out.csv"], "does not exist", "--csv")
option("plot_no_folder", ["simulate", F, "--plot", "nodir/p.png"], "does not exist", "--plot")
option("bode_no_folder", ["analyze", F, "--bode", "nodir/b.png"], "does not exist", "--bode")
option(
    "sweep_plot_no_folder",
    ["sweep", F, "--param", "R1=1,2", "--plot", "nodir/l.png"],
    "does not exist",
    "--plot",
)
option("validate_out_no_folder", ["validate", F, "-o", "nodir/v.txt"], "does not exist", "-o")
option("missing_netlist", ["analyze", "nothere.cir"], "does not exist", "nothere.cir")
option("netlist_is_directory", ["analyze", "."], "directory", "'.'")
option("no_netlist", ["analyze"], "Missing argument", "NETLIST")
option("unknown_command", ["analyse", F], "No such command", "analyse")
option("unknown_option", ["analyze", F, "--frobnicate"], "No such option", "--frobnicate")
option("symbolic_minimal", ["analyze", F, "--symbolic", "--minimal"], "--minimal", "--symbolic")
option("connect_bad_how", ["connect", "parallel", F, F], "Invalid value", "parallel")
option("connect_sign_bogus", ["connect", "series", F, F, "--sign", "2"], "Invalid value", "--sign")

# --- issue 29: outputs that are inputs, references on every command, non-ASCII digits, work ----
# An output that is an input (the netlist, an .include file, a model given to connect) is refused
# before any work: nothing is written, the input is intact.
option("out_is_netlist", ["analyze", F, "-o", F], "refusing to overwrite", "-o")
option("csv_is_netlist", ["simulate", F, "--csv", F], "refusing to overwrite", "--csv")
option("save_is_netlist", ["analyze", F, "--save", "m.json", "--bode", F], "refusing to overwrite", "--bode")
option("op_out_is_netlist", ["op", F, "-o", F], "refusing to overwrite", "-o")
option("sweep_out_is_netlist", ["sweep", F, "--param", "R1=1,2", "-o", F], "refusing to overwrite", "-o")
_add(
    "out_is_include.cir",
    ["simulate", "{file}", "--plot", "aux_included.inc"],
    2,
    "--plot",
    "refusing to overwrite",
    text=TITLE + "V1 a 0 1\nR1 a 0 1\n.include aux_included.inc\n",
)
_add(
    "connect_out_is_model.json",
    ["connect", "series", "{file}", "{file}", "-o", "{file}"],
    2,
    "-o",
    "refusing to overwrite",
    text=json.dumps(
        {"states": ["q"], "inputs": ["u"], "outputs": ["y"], "A": [[-1]], "B": [[1]], "C": [[1]], "D": [[0]]}
    ),
)
# References are checked by one pass after parsing, so op and the nonlinear simulate (a diode
# makes the netlist nonlinear) refuse them as analyze does, at the element's line.
D = "D1 a 0 dm\n.model dm D\n"
for command in ("op", "simulate", "analyze"):
    netlist(
        f"nonlinear_unknown_control_node_{command}",
        V + "R1 a 0 1\nE1 b 0 zz 0 2\nR2 b 0 1\n" + D,
        4,
        "'zz'",
        args=[command, "{file}"],
    )
    netlist(
        f"nonlinear_unknown_sense_source_{command}",
        V + "R1 a 0 1\nF1 b 0 Vx 2\nR2 b 0 1\n" + D,
        4,
        "not a voltage source",
        args=[command, "{file}"],
    )
    netlist(
        f"nonlinear_unknown_coupled_inductor_{command}",
        V + "R1 a b 1\nL1 b 0 1\nK1 L1 L2 0.5\n" + D,
        5,
        "not an inductor",
        args=[command, "{file}"],
    )
# Digits are ASCII: ngspice 39 refuses full-width and Arabic-Indic digits and superscripts.
netlist("param_superscript", ".param R1=\u00b2\n" + V + "R1 a 0 {R1}\n", 2, "'\u00b2'")
netlist("full_width_digit", V + "R1 a 0 \uff11k\n", 3, "R1")
netlist("arabic_indic_digits", V + "R1 a 0 {\u0661\u0660\u0660\u0660}\n", 3, "R1")

# --- saved models for connect -------------------------------------------------------------
MODEL = {
    "title": "one RC",
    "states": ["q(C1)"],
    "inputs": ["V1"],
    "outputs": ["v(a)"],
    "A": [[-1.0]],
    "B": [[1.0]],
    "C": [[1.0]],
    "D": [[0.0]],
}


def model(name: str, doc: Any, fragment: str) -> None:
    data = doc if isinstance(doc, bytes) else (doc if isinstance(doc, str) else json.dumps(doc)).encode()
    raw(name, data, ["connect", "series", "{file}", "{file}"], 2, "{file}", fragment)


model("model_malformed.json", '{"states": ["q(C1)"], ', "not valid JSON")
model("model_no_states.json", {k: v for k, v in MODEL.items() if k != "states"}, "no 'states'")
model("model_no_A.json", {k: v for k, v in MODEL.items() if k != "A"}, "no matrix A")
model("model_wrong_A_shape.json", {**MODEL, "A": [[1.0, 2.0], [3.0, 4.0]]}, "A has shape (2, 2)")
model("model_ragged_A.json", {**MODEL, "A": [[1.0, 2.0], [3.0]]}, "A")
model(
    "model_nan_in_A.json",
    '{"states": ["q"], "inputs": ["u"], "outputs": ["y"], "A": [[NaN]], "B": [[1]], "C": [[1]], "D": [[0]]}',
    "not finite",
)
model(
    "model_inf_in_B.json",
    '{"states": ["q"], "inputs": ["u"], "outputs": ["y"], '
    '"A": [[-1]], "B": [[Infinity]], "C": [[1]], "D": [[0]]}',
    "not finite",
)
model("model_strings_in_C.json", {**MODEL, "C": [["one"]]}, "not a matrix of real numbers")
model(
    "model_100000_states.json",
    {**MODEL, "states": [f"x{k}" for k in range(100_000)]},
    "A has shape (1, 1), expected (100000, 100000)",
)
model("model_states_not_list.json", {**MODEL, "states": "q(C1)"}, "not a list")
model(
    "model_repeated_state.json",
    {**MODEL, "states": ["q", "q"], "A": [[0, 0], [0, 0]], "B": [[1], [1]], "C": [[1, 1]]},
    "repeats a name",
)
model("model_array.json", [1, 2, 3], "not a model")
model("model_empty.json", b"", "not valid JSON")
model("model_binary.json", bytes(range(256)), "not valid JSON")
model(
    "model_coo_out_of_range.json",
    {**MODEL, "A": {"format": "coo", "shape": [1, 1], "row": [5], "col": [0], "data": [1.0]}},
    "outside the shape",
)
model("model_coo_unknown_format.json", {**MODEL, "A": {"format": "csr"}}, "unknown matrix format")


def npz(arrays: dict[str, Any]) -> bytes:
    import io

    import numpy as np

    buffer = io.BytesIO()
    np.savez(buffer, **{k: np.asarray(v) for k, v in arrays.items()})
    return buffer.getvalue()


def pickled_npz() -> bytes:
    import io

    import numpy as np

    buffer = io.BytesIO()
    np.savez(buffer, A=np.array([{"evil": 1}], dtype=object), states=np.array(["q"]))
    return buffer.getvalue()


def truncated(data: bytes) -> bytes:
    return data[: len(data) // 2]


GOOD_NPZ = npz({**{k: v for k, v in MODEL.items() if k != "title"}, "title": "one RC"})
model("model_pickled.npz", pickled_npz(), "not a readable .npz model")
model("model_truncated.npz", truncated(GOOD_NPZ), "not a readable .npz model")
model("model_not_zip.npz", b"this is not a zip archive\n", "not a readable .npz model")
model("model_no_states.npz", npz({"A": [[1.0]]}), "no 'states'")
model(
    "model_wrong_shape.npz",
    npz({**{k: v for k, v in MODEL.items() if k != "title"}, "A": [[1.0, 2.0]]}),
    "A has shape (1, 2)",
)
model(
    "model_nan.npz",
    npz({**{k: v for k, v in MODEL.items() if k != "title"}, "A": [[float("nan")]]}),
    "not finite",
)
model(
    "model_plain_npy.npz",
    b"\x93NUMPY\x01\x00v\x00{'descr': '<f8', 'fortran_order': False, 'shape': (1,), }"
    + b" " * 43
    + b"\n"
    + struct.pack("<d", 1.0),
    "model",
)
model("model_corrupt.mat", b"MATLAB 5.0 MAT-file, corrupt" + bytes(100), "not a readable .mat model")
model("model_text.mat", b"A = [1 2; 3 4]\n", "not a readable .mat model")
model("model_empty.npz", b"", "not a readable .npz model")


def zip_with_member() -> bytes:
    import io

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for member, content in (("A.npy", b"not an npy file"), ("states.npy", b"also not")):
            archive.writestr(zipfile.ZipInfo(member, date_time=(2026, 1, 1, 0, 0, 0)), content)
    return buffer.getvalue()


model("model_bad_member.npz", zip_with_member(), "not a readable .npz model")


def write() -> None:
    for old in HERE.iterdir():
        if old.name not in ("make_inputs.py", "__init__.py"):
            old.unlink()
    manifest = []
    for case in CASES:
        path = HERE / case["file"]
        assert not path.exists(), case["file"]
        if "bytes" in case:
            path.write_bytes(case.pop("bytes"))
        else:
            path.write_bytes(case.pop("text").encode())
        manifest.append(case)
    # Auxiliary files named by the .include cases (not cases themselves).
    (HERE / "binary.bin").write_bytes(bytes(range(256)) * 8)
    (HERE / "aux_included.inc").write_text("* an included file (an output naming it is refused)\nR9 a 0 1k\n")
    (HERE / "manifest.json").write_text(json.dumps(manifest, indent=1, ensure_ascii=False) + "\n")
    print(f"{len(manifest)} cases")


if __name__ == "__main__":
    write()
