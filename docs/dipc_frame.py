"""Write docs/dipc_frame.png, the animation frame shown in the README.

The same pipeline as ``netlistdyn simulate netlists/dipc.cir --ic 'angle(r1)=-0.01'
--ic 'angle(r2)=-0.02' --animate dipc.gif``: one frame, at t = 0.5 s.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from netlistdyn.analysis.coordinates import prepare
from netlistdyn.frontend.parser import parse_file
from netlistdyn.io.animate import Animation, Options, position_variables
from netlistdyn.simulation import integrators
from netlistdyn.simulation.foh import input_signals

HERE = Path(__file__).resolve().parent


def main() -> None:
    """Simulate the notes' DIPC run for 0.5 s and save its last frame as a small PNG."""
    parsed = parse_file(HERE.parent / "netlists" / "dipc.cir")
    prepared = prepare(parsed, None, None, ["angle(r1)=-0.01", "angle(r2)=-0.02"], position_variables(parsed))
    times = np.linspace(0.0, 0.5, 501)
    signals = input_signals(parsed, 1e-3, 0.5)
    run = integrators.run(prepared.full, signals, times, x0=prepared.x0)
    movie = Animation(
        parsed, run.time, run.outputs, prepared.full.outputs, signals(run.time), Options(10, 1, (480, 270))
    )
    frame = movie.render(len(movie.frames()) - 1)
    Image.fromarray(frame).convert("P", palette=Image.Palette.ADAPTIVE, colors=32).save(
        HERE / "dipc_frame.png", optimize=True
    )


if __name__ == "__main__":
    main()
