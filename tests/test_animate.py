"""Issue 18: animations are a view of the simulation simulate reports.

Positions are checked on rendered frames: the pixels of each bob (its own
colour) are located, converted to drawing coordinates and compared with
where the simulated outputs put it. PIXEL_TOL: a centroid of an
antialiased disc is within ~1 pixel of its centre; a wrong angle, sign or
sample time moves a bob by many pixels.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy import ndimage

from netlistdyn.analysis.coordinates import prepare
from netlistdyn.cli import main
from netlistdyn.frontend.parser import parse_file
from netlistdyn.io.animate import BLOCK_COLOUR, BOB_COLOUR, Animation, Options, position_variables
from netlistdyn.simulation import integrators
from netlistdyn.simulation.foh import input_signals

from .conftest import NETLISTS

PIXEL_TOL = 1.5
DIPC_IC = ["--ic", "angle(r1)=-0.01", "--ic", "angle(r2)=-0.02"]


def test_dipc_gif_has_the_requested_frames_and_size(tmp_path: Path) -> None:
    from PIL import Image

    target = tmp_path / "dipc.gif"
    result = CliRunner().invoke(
        main,
        [
            "simulate",
            str(NETLISTS / "dipc.cir"),
            *DIPC_IC,
            "--tstop",
            "0.5",
            "--fps",
            "20",
            "--frame-size",
            "320x200",
            "--animate",
            str(target),
            "--format",
            "json",
            "--output",
            "angle(r1)",
            "--output",
            "angle(r2)",
        ],
    )
    assert result.exit_code == 0, result.output
    with Image.open(target) as gif:
        assert gif.size == (320, 200)
        assert gif.n_frames == 11  # 0.5 s at 20 frames per second, both ends included
    doc = json.loads(result.stdout)
    assert doc["values"]["angle(r1)"][0] == pytest.approx(-0.01, rel=1e-12)


def _colour(hex_colour: str) -> np.ndarray:
    return np.array([int(hex_colour[k : k + 2], 16) for k in (1, 3, 5)])


def _blobs(frame: np.ndarray, colour: str, count: int) -> list[tuple[float, float]]:
    """Bounding-box centres (row, col) of the ``count`` largest regions of exactly this colour
    (labels and pivot dots inside a shape leave its outline, hence its box, unchanged)."""
    mask = np.all(frame == _colour(colour), axis=2)
    labels, n = ndimage.label(mask)
    sizes = ndimage.sum(mask, labels, range(1, n + 1))
    biggest = np.argsort(sizes)[::-1][:count]
    boxes = ndimage.find_objects(labels)
    return [
        ((boxes[j][0].start + boxes[j][0].stop - 1) / 2, (boxes[j][1].start + boxes[j][1].stop - 1) / 2)
        for j in biggest
    ]


def test_drawn_positions_equal_the_simulated_outputs() -> None:
    parsed = parse_file(NETLISTS / "dipc.cir")
    prepared = prepare(parsed, None, None, ["angle(r1)=-0.01", "angle(r2)=-0.02"], position_variables(parsed))
    full = prepared.full
    times = np.linspace(0.0, 0.6, 601)
    signals = input_signals(parsed, 1e-3, 0.6)
    run = integrators.run(full, signals, times, x0=prepared.x0)
    assert run.ok
    movie = Animation(
        parsed, run.time, run.outputs, full.outputs, signals(run.time), Options(10, 1, (480, 320))
    )
    assert len(movie.frames()) == 7
    col = {n: k for k, n in enumerate(full.outputs)}
    l1 = 0.5 * movie.scene.rod_scale
    l2 = 0.75 * movie.scene.rod_scale
    for k in (0, 3, 6):
        sample = movie.frames()[k]
        assert run.time[sample] == pytest.approx(k * 0.1, abs=1e-12)
        y = run.outputs[sample]
        # Independently of the animation's own layout: cart on the track, rods from its top.
        cart = (movie.rest("cart") + y[col["x(cart)"]], 0.0)
        pivot = (cart[0], movie.block / 2)
        t1, t2 = y[col["angle(r1)"]], y[col["angle(r2)"]]
        bob1 = (pivot[0] + l1 * math.sin(t1), pivot[1] + l1 * math.cos(t1))
        bob2 = (bob1[0] + l2 * math.sin(t2), bob1[1] + l2 * math.cos(t2))
        frame = movie.render(k)
        assert frame.shape == (320, 480, 3)
        pixel = movie.to_data(0, 1)[0] - movie.to_data(0, 0)[0]
        found = [movie.to_data(*c) for c in _blobs(frame, BOB_COLOUR, 2)]
        for expected in (bob1, bob2):
            miss = min(math.dist(expected, f) for f in found)
            assert miss < PIXEL_TOL * abs(pixel), (k, expected, found)
        (block,) = [movie.to_data(*c) for c in _blobs(frame, BLOCK_COLOUR, 1)]
        assert abs(block[0] - cart[0]) < PIXEL_TOL * abs(pixel)


def test_frames_are_the_reported_simulation(tmp_path: Path) -> None:
    """--animate does not change what simulate reports (same run, same times)."""
    args = ["simulate", str(NETLISTS / "blocks_pendulum.cir"), "--output", "angle(rod)", "--format", "json"]
    plain = CliRunner().invoke(main, [*args, "--tstop", "4"])
    with_movie = CliRunner().invoke(
        main,
        [
            *args,
            "--tstop",
            "4",
            "--fps",
            "2",
            "--frame-size",
            "160x120",
            "--animate",
            str(tmp_path / "a.gif"),
        ],
    )
    assert plain.exit_code == 0 and with_movie.exit_code == 0, with_movie.output
    a, b = json.loads(plain.stdout), json.loads(with_movie.stdout)
    assert a["time"] == b["time"]
    peak = max(abs(v) for v in a["values"]["angle(rod)"])
    diff = max(abs(p - q) for p, q in zip(a["values"]["angle(rod)"], b["values"]["angle(rod)"], strict=True))
    # The movie adds displacement outputs (and their integrator states); the angle is unchanged
    # up to rounding of the exact method (~1e-13 of the peak).
    assert diff <= 1e-10 * peak


def test_electrical_netlist_has_nothing_to_animate(tmp_path: Path) -> None:
    target = tmp_path / "c1.gif"
    result = CliRunner().invoke(main, ["simulate", str(NETLISTS / "circuit1.cir"), "--animate", str(target)])
    assert result.exit_code == 2
    assert "no mechanical element" in result.output and "--plot" in result.output
    assert not target.exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--animate", "x.avi"], "use a .gif or .mp4"),
        (["--animate", "x.gif", "--frame-size", "big"], "expected WxH"),
        (["--animate", "x.gif", "--fps", "0"], "--fps must be"),
        (["--animate", "x.gif", "--geometry", "size=2"], "expected spacing=M or rod_scale=F"),
    ],
)
def test_bad_animation_options(args, message, tmp_path: Path) -> None:
    args = [a if not a.startswith("x.") else str(tmp_path / a) for a in args]
    result = CliRunner().invoke(main, ["simulate", str(NETLISTS / "two_blocks.cir"), *args])
    assert result.exit_code == 2
    assert message in result.output


@pytest.mark.skipif(shutil.which("ffmpeg") is not None, reason="ffmpeg is installed here")
def test_mp4_without_ffmpeg_says_so(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        main, ["simulate", str(NETLISTS / "two_blocks.cir"), "--animate", str(tmp_path / "a.mp4")]
    )
    assert result.exit_code == 2
    assert "needs ffmpeg" in result.output


@pytest.mark.parametrize(
    "name",
    [
        "two_blocks.cir",
        "blocks_pendulum.cir",
        "double_pendulum.cir",
        "dipc.cir",
        "two_pendula_cart.cir",
        "servo_shaft.cir",
    ],
)
def test_every_mechanical_netlist_is_drawn_inside_the_frame(name) -> None:
    """At the start and at 0.3 s every bob is drawn whole, inside the picture."""
    parsed = parse_file(NETLISTS / name)
    prepared = prepare(parsed, None, None, (), position_variables(parsed))
    times = np.linspace(0.0, 0.3, 31)
    signals = input_signals(parsed, 0.01, 0.3)
    run = integrators.run(prepared.full, signals, times)
    movie = Animation(
        parsed, run.time, run.outputs, prepared.full.outputs, signals(run.time), Options(10, 1, (320, 200))
    )
    rods = len(movie.scene.rods)
    for k in (0, len(movie.frames()) - 1):
        frame = movie.render(k)
        mask = np.all(frame == _colour(BOB_COLOUR), axis=2)
        _, found = ndimage.label(mask)
        assert found == rods
        if rods:
            rows, cols = np.nonzero(mask)
            assert rows.min() > 0 and cols.min() > 0 and rows.max() < 199 and cols.max() < 319


@pytest.mark.skipif(shutil.which("ffmpeg") is None or shutil.which("ffprobe") is None, reason="needs ffmpeg")
def test_mp4_with_ffmpeg(tmp_path: Path) -> None:
    import subprocess

    target = tmp_path / "a.mp4"
    result = CliRunner().invoke(
        main,
        [
            "simulate",
            str(NETLISTS / "two_blocks.cir"),
            "--tstop",
            "2",
            "--fps",
            "10",
            "--frame-size",
            "320x180",
            "--animate",
            str(target),
        ],
    )
    assert result.exit_code == 0, result.output
    probe = subprocess.run(
        [
            "ffprobe",
            "-v",
            "error",
            "-count_frames",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=nb_read_frames,width,height",
            "-of",
            "csv=p=0",
            str(target),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    assert probe.stdout.strip() == "320,180,21"
