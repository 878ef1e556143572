"""Robustness of the command line: atomic writes, option checks, saved models, deep valid input."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from netlistdyn.base import atomic
from netlistdyn.base.errors import UsageError
from netlistdyn.cli import main
from netlistdyn.formulation.compile import compile_netlist
from netlistdyn.frontend.parser import parse_text
from netlistdyn.io.exports import load_model, save_model
from netlistdyn.spice.ngspice import ngspice_missing

ROOT = Path(__file__).resolve().parent.parent
CIRCUIT1 = str(ROOT / "netlists" / "circuit1.cir")


def run(args: list[str], stdin: str | None = None) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, args, input=stdin)
    return result.exit_code, result.stdout, result.stderr


# --- atomic writes -------------------------------------------------------------------------


def test_new_file_respects_umask_and_existing_mode_is_kept(tmp_path: Path) -> None:
    old = os.umask(0o027)
    try:
        atomic.write_text(tmp_path / "new.txt", "x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "new.txt").stat().st_mode) == 0o640
    existing = tmp_path / "old.txt"
    existing.write_text("old")
    existing.chmod(0o604)
    atomic.write_text(existing, "new")
    assert existing.read_text() == "new"
    assert stat.S_IMODE(existing.stat().st_mode) == 0o604
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.txt", "old.txt"]


def test_symlink_is_written_through(tmp_path: Path) -> None:
    real = tmp_path / "real.txt"
    real.write_text("old")
    link = tmp_path / "link.txt"
    link.symlink_to(real.name)
    atomic.write_text(link, "new")
    assert link.is_symlink()
    assert real.read_text() == "new"


def test_fifo_is_written_through(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
    reader.start()
    atomic.write_text(fifo, "through the pipe")
    reader.join(timeout=10)
    assert got == [b"through the pipe"]
    assert stat.S_ISFIFO(fifo.stat().st_mode)


def test_error_names_the_users_path_not_the_temporary(tmp_path: Path) -> None:
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        if os.access(folder, os.W_OK):
            pytest.skip("running as a user who may write anywhere")
        with pytest.raises(OSError) as info:
            atomic.write_text(folder / "out.txt", "x")
        assert info.value.filename == str(folder / "out.txt")
    finally:
        folder.chmod(0o700)


def test_failed_write_leaves_no_temporary(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(*_args: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic.os, "replace", broken)
    with pytest.raises(OSError) as info:
        atomic.write_text(tmp_path / "out.txt", "x")
    assert info.value.filename == str(tmp_path / "out.txt")
    assert list(tmp_path.iterdir()) == []


def test_sigterm_during_write_removes_the_temporary(tmp_path: Path) -> None:
    """A child process writing a large file is terminated while its temporary exists."""
    script = f"""
import os, signal, sys, time
sys.path.insert(0, {str(ROOT)!r})
from netlistdyn.base import atomic
atomic.install_signal_cleanup()
real_replace = os.replace
def slow_replace(a, b):
    print("written", flush=True)
    time.sleep(30)
    real_replace(a, b)
os.replace = slow_replace
atomic.write_bytes({str(tmp_path / "big.bin")!r}, b"x" * 10_000_000)
"""
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "written"
    assert any(p.name.endswith(".tmp") and "netlistdyn" in p.name for p in tmp_path.iterdir())
    proc.terminate()
    assert proc.wait(timeout=20) == -15
    assert list(tmp_path.iterdir()) == []


# --- command line ------------------------------------------------------------------------


def test_dash_reads_stdin_and_writes_stdout() -> None:
    code, out, err = run(["analyze", "-", "-o", "-"], Path(CIRCUIT1).read_text())
    assert code == 0, err
    assert "q(C1)" in out


def test_stdin_error_names_stdin() -> None:
    code, _, err = run(["analyze", "-"], "title\nV1 a 0 1\nR1 a 0 0\n")
    assert code == 1
    assert err.startswith("<stdin>:3: R1")


@pytest.mark.skipif(ngspice_missing() is not None, reason="ngspice is not installed")
def test_validate_reads_stdin() -> None:
    """``validate -`` runs ngspice on the text of standard input (and its original-file check)."""
    text = "RC low-pass\nV1 in 0 PULSE(0 1 0 1u 1u 1m 2m)\nR1 in a 1k\nC1 a 0 100n\n.tran 10u 2m\n"
    code, out, err = run(["validate", "-", "--no-pz"], text)
    assert code == 0, err
    assert "PASS" in out and "original file" in out
    code, _, err = run(["validate", "-"], "title\nV1 a 0 1\nR1 a 0 0\n")
    assert code == 1
    assert err.startswith("<stdin>:3: R1")


def test_outputs_are_checked_before_any_work(tmp_path: Path) -> None:
    save = tmp_path / "m.npz"
    code, _, err = run(["analyze", CIRCUIT1, "--save", str(save), "-o", str(tmp_path / "nodir" / "out.txt")])
    assert code == 2
    assert "-o" in err and "does not exist" in err
    assert not save.exists()
    code, _, err = run(["analyze", CIRCUIT1, "--save", str(tmp_path / "m.xyz")])
    assert code == 2 and "unknown format" in err


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["sweep", CIRCUIT1, "--param", "r1=lin:1:2:²"], "COUNT"),
        (["sweep", CIRCUIT1, "--param", "r1=lin:1:2:10000000000"], "--max-cases"),
        (["sweep", CIRCUIT1, "--param", "r1=lin:1e400:1:5"], "not a finite number"),
        (["sweep", CIRCUIT1, "--param", "r1=1,2", "--scheduler", "bogus"], "--scheduler"),
        (["sweep", CIRCUIT1, "--param", "r1=lin:1:2:400", "--param", "r2=lin:1:2:300"], "120,000 cases"),
        (["simulate", CIRCUIT1, "--tstop", "inf"], "--tstop"),
        (["simulate", CIRCUIT1, "--tstep", "nan"], "--tstep"),
        (["simulate", CIRCUIT1, "--ic", "q(C1)=" + "9" * 5000], "--ic"),
        (["analyze", CIRCUIT1, "--param", "R1=" + "1" * 5000], "--param"),
        (["bench", CIRCUIT1, "--points", "1" * 5000], "--points"),
    ],
)
def test_bad_options_one_line_exit_2(args: list[str], fragment: str) -> None:
    code, _out, err = run(args)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1, err
    assert fragment in err
    assert len(err) < 400


def test_sweep_where_every_case_fails_exits_1() -> None:
    code, _, err = run(["sweep", CIRCUIT1, "--param", "r1=0,0"])
    assert code == 1
    assert "R1" in err and "every one of the 2 cases failed" in err


def test_jobs_capped_at_cpus() -> None:
    code, out, err = run(["sweep", CIRCUIT1, "--param", "r1=1,2", "--jobs", "500"])
    assert code == 0
    assert "capped" in err
    assert out.count("stable") == 2


def test_bench_without_sources_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "nosrc.cir"
    path.write_text("no source\nR1 a 0 1\nC1 a 0 1u\n")
    code, _, err = run(["bench", str(path), "--no-ngspice"])
    assert code == 1 and err.startswith(f"{path}:1:") and "source" in err


# --- saved models ------------------------------------------------------------------------

SMALL = "small\nV1 in 0 1\nR1 in a 1k\nC1 a 0 1u\nL1 a 0 1m\n"


def small_model() -> object:
    return compile_netlist(parse_text(SMALL))


@pytest.mark.parametrize("suffix", [".json", ".npz", ".mat"])
def test_large_models_saved_sparse_round_trip(tmp_path: Path, suffix: str) -> None:
    lines = ["ladder", "V1 n0 0 1"]
    for k in range(1, 1201):
        lines += [f"R{k} n{k - 1} n{k} 1", f"C{k} n{k} 0 1u", f"L{k} n{k} 0 1m"]
    model = compile_netlist(parse_text("\n".join(lines) + "\n"), ["v(n5)"])
    assert model.nstates > 2000
    path = tmp_path / f"big{suffix}"
    save_model(model, path)
    back = load_model(path)
    assert back.states == model.states
    diff = abs(back.A_sparse - model.A_sparse).max()
    assert diff <= 1e-15 * abs(model.A_sparse).max()  # binary formats and JSON's repr are exact
    assert path.stat().st_size < 2_000_000  # dense A alone would be 46 MB


def bad_model_files(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    model = small_model()
    good = tmp_path / "good.json"
    save_model(model, good)
    doc = json.loads(good.read_text())
    files: dict[str, tuple[Path, str]] = {}

    def json_file(name: str, content: object, fragment: str) -> None:
        path = tmp_path / f"{name}.json"
        path.write_text(content if isinstance(content, str) else json.dumps(content))
        files[name] = (path, fragment)

    json_file("malformed", '{"states": [', "not valid JSON (line 1")
    json_file("no_states", {k: v for k, v in doc.items() if k != "states"}, "no 'states'")
    json_file("wrong_shape", {**doc, "A": [[1.0]]}, "A has shape (1, 1), expected (2, 2)")
    json_file("nan", {**doc, "A": [[float("nan"), 0], [0, 1]]}, "not finite")
    json_file("many_states", {**doc, "states": [f"s{k}" for k in range(100_000)]}, "A has shape (2, 2)")
    json_file("a_list", [1, 2, 3], "not a model")
    json_file("strings", {**doc, "A": [["a", "b"], ["c", "d"]]}, "not a matrix of real numbers")
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, A=np.array([object()], dtype=object), states=np.array(["x"]))
    files["pickled"] = (pickled, "not a readable .npz model")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"PK\x03\x04" + os.urandom(200))
    files["corrupt_npz"] = (corrupt, "not a readable .npz model")
    mat = tmp_path / "corrupt.mat"
    mat.write_bytes(b"MATLAB 5.0 MAT-file" + bytes(200))
    files["corrupt_mat"] = (mat, "not a readable .mat model")
    return files


def test_bad_saved_models_are_refused(tmp_path: Path) -> None:
    for name, (path, fragment) in bad_model_files(tmp_path).items():
        with pytest.raises(UsageError) as info:
            load_model(path)
        assert fragment in str(info.value), (name, str(info.value))
        assert str(path) in str(info.value)
        code, _out, err = run(["connect", "series", str(path), str(path)])
        assert code == 2, (name, err)
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


# --- deep valid input ----------------------------------------------------------------------


def test_hanging_chain_of_600_rods() -> None:
    """Valid deep input: each rod carries the masses below it (g = 9.81 by default)."""
    lines = ["chain"]
    for k in range(1, 601):
        lines += [f"ROD r{k} {'0' if k == 1 else f'b{k - 1}'} b{k} 0.1", f"MASS m{k} b{k} 0.01"]
    lines.append("FORCE push b600 0 1")
    netlist = parse_text("\n".join(lines) + "\n")
    tension = {e.name.lower(): e.rod.tension for e in netlist.elements if e.rod is not None}
    assert tension["r1"] == pytest.approx(9.81 * 600 * 0.01, rel=1e-12)
    assert tension["r300"] == pytest.approx(9.81 * 301 * 0.01, rel=1e-12)
    assert tension["r600"] == pytest.approx(9.81 * 0.01, rel=1e-12)
    model = compile_netlist(netlist, ["x(b600)"])
    # 600 momenta and 600 rod forces; the bob's position is the sum of the rods' stretches (the chain
    # hangs from the frame), so it needs no integrator.
    assert model.nstates == 1200 and model.info.integrators == ()


# --- validate under faults -----------------------------------------------------------------

needs_ngspice = pytest.mark.skipif(ngspice_missing() is not None, reason=str(ngspice_missing()))


@needs_ngspice
def test_broken_libngspice_is_unusable_exit_4(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NGSPICE_LIBRARY_PATH", "/etc/passwd")  # not a shared library
    code, out, err = run(["validate", CIRCUIT1, "--no-pz"])
    assert code == 4, err
    assert out == ""
    assert err.startswith("netlistdyn: ngspice unusable: libngspice cannot be loaded")
    assert len(err.strip().splitlines()) == 1


@needs_ngspice
def test_pyspice_import_failure_is_unusable_exit_4(tmp_path: Path) -> None:
    fake = tmp_path / "PySpice"
    fake.mkdir()
    (fake / "__init__.py").write_text("raise ImportError('broken for the test')\n")
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}"}
    proc = subprocess.run(
        [sys.executable, "-m", "netlistdyn", "validate", CIRCUIT1, "--no-pz"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert proc.returncode == 4, proc.stderr
    assert (
        proc.stderr.strip()
        == "netlistdyn: ngspice unusable: PySpice cannot be imported (broken for the test)"
    )


@needs_ngspice
def test_ngspice_timeout_has_its_own_exit_code() -> None:
    code, out, err = run(["validate", CIRCUIT1, "--no-pz", "--timeout", "1e-3"])
    assert code == 5, err
    assert "did not finish within 0.001 s" in err and out == ""


@needs_ngspice
def test_dc_value_with_pulse_gets_a_reference(tmp_path: Path) -> None:
    """ngspice prints a "Note:" on stderr for DC next to PULSE; it is not an error."""
    text = Path(CIRCUIT1).read_text().replace("Vin in 0 DC 1", "Vin in 0 DC 10 PULSE(0 1 0 1u 1u 1m 2m)")
    assert "PULSE" in text
    path = tmp_path / "dcpulse.cir"
    path.write_text(text)
    code, out, err = run(["validate", str(path), "--tstop", "5m", "--no-pz"])
    assert code == 0, out + err
    assert "PASS" in out
