"""Output grids that show what the outputs do (issue: an aliased waveform, without a word).

The reference in each test is the same circuit on a grid 100x finer than the one checked: the
property under test is where the samples are, not how accurately each is computed (the exact method's
own error is below 1e-9 of the peak here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import netlistdyn
from netlistdyn.simulation.sampling import REFINED_SAMPLES_PER_PERIOD, SAMPLES_PER_PERIOD

#: An RLC low-pass with realistic values (10 Ω, 10 µH, 100 nF, 1 kΩ): a 138 kHz mode with ζ = 0.5
#: under LTspice's one-argument .tran, whose TSTEP = TSTOP/50 = 4 µs gives 1.8 samples per period.
LOW_PASS = """RLC low-pass, LTspice-style one-argument .tran
V1 in 0 PULSE(0 1 0 1n 1n 1 2)
R1 in a 10
L1 a out 10u
C1 out 0 100n
R2 out 0 1k
.tran 200u
.end
"""
#: A 10 µs pulse every 1 ms into an RC: a 1 ms grid lands every sample in the low phase.
PULSE_TRAIN = """pulse train
V1 in 0 PULSE(0 1 0.5m 1n 1n 10u 1m)
R1 in out 1k
C1 out 0 1n
.tran 1m 20m
.end
"""
#: The worst fraction of the peak a 20-samples-per-period grid can miss of a sinusoid's crest:
#: 1 − cos(π/20) = 0.0123; the refined grid must find the crest within it.
CREST_MISS = 1 - np.cos(np.pi / REFINED_SAMPLES_PER_PERIOD)


def _peak(sim: netlistdyn.Simulation, name: str) -> float:
    return float(sim.values[:, sim.outputs.index(name)].max())


def test_tran_grid_is_refined_to_the_fastest_visible_mode(tmp_path: Path) -> None:
    path = tmp_path / "lowpass.cir"
    path.write_text(LOW_PASS)
    sim = netlistdyn.simulate(path)
    warnings = sim.warnings
    fine = netlistdyn.simulate(path, tstop="200u", tstep="3.6n")
    # 138.3 kHz: period 7.23 µs; 20 samples per period
    assert sim.horizon.tstep < 7.23e-6 / SAMPLES_PER_PERIOD
    assert abs(_peak(sim, "v(out)") - _peak(fine, "v(out)")) <= CREST_MISS * _peak(fine, "v(out)")
    assert any("refined" in w and "138.3 kHz" in w for w in warnings), warnings
    assert any(w.startswith(f"{path}:7:") for w in warnings if "refined" in w)


def test_a_users_coarse_step_is_kept_and_named(tmp_path: Path) -> None:
    path = tmp_path / "lowpass.cir"
    path.write_text(LOW_PASS)
    sim = netlistdyn.simulate(path, tstop="200u", tstep="4u")
    warnings = sim.warnings
    assert sim.time.size == 51  # the user's grid, as asked
    assert any("undersamples the 138.3 kHz mode" in w for w in warnings), warnings


def test_pulse_corners_join_a_coarse_tran_grid(tmp_path: Path) -> None:
    path = tmp_path / "train.cir"
    path.write_text(PULSE_TRAIN)
    sim = netlistdyn.simulate(path)
    warnings = sim.warnings
    assert _peak(sim, "v(in)") > 1 - 1e-9  # without the corners every sample is 0 V
    corners = 0.5e-3 + np.arange(20) * 1e-3
    assert np.all(np.min(np.abs(sim.time[:, None] - corners[None, :]), axis=0) < 1e-15)
    assert any("corners" in w for w in warnings), warnings
    kept = netlistdyn.simulate(path, tstop="20m", tstep="1m")
    assert _peak(kept, "v(in)") < 1e-12 and any("can miss its pulses" in w for w in kept.warnings)


def test_a_well_sampled_grid_is_left_alone(tmp_path: Path) -> None:
    path = tmp_path / "lowpass.cir"
    path.write_text(LOW_PASS.replace(".tran 200u", ".tran 100n 200u"))
    sim = netlistdyn.simulate(path)
    assert sim.time.size == 2001 and not sim.warnings


def test_a_nearly_defective_model_is_left_unchecked_without_noise() -> None:
    """The DIPC's linearisation has a free cart (a double zero eigenvalue): its eigenvectors are nearly
    dependent, no modal share is trustworthy, and the check stays silent (it printed numpy's overflow)."""
    from click.testing import CliRunner

    from netlistdyn.cli import main

    args = ["simulate", "netlists/planar/dipc.cir", "--tstop", "0.5", "--ic", "angle(r1)=-0.01", "-q"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "floating-point trouble" not in result.output and "warning" not in result.output
