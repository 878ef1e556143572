"""Animations of planar mechanisms: the points where the exact simulation put them.

Every frame draws the mechanism at one simulated sample (the nearest to ``k · speed / fps``, as
:class:`netlistdyn.io.animate.Animation` chooses them): each slider's track as a grey line through
its base, fixed points as hatched triangles, rods as lines between their points, bodies on a
slider as blocks along the track and other bodies as discs (area ∝ mass), springs as zigzags and
dampers as pistons along the line between their points, and an arrow showing gravity. Positions
come from the ``px(point)``, ``py(point)`` outputs of the run (:func:`position_variables`);
nothing is re-simulated. Drawing coordinates are metres, with equal scales on both axes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from netlistdyn.base.errors import UsageError
from netlistdyn.circuit.netlist import Netlist
from netlistdyn.formulation.planar import Mechanism, mechanism_tree
from netlistdyn.io.animate import MAX_FRAMES, Animation, Options


def position_variables(netlist: Netlist) -> list[str]:
    """The outputs an animation of the planar ``netlist`` reads: every point's ``px``, ``py``."""
    points = mechanism_tree(netlist).points
    return [f"{axis}({p})" for p in points for axis in ("px", "py")]


class PlanarAnimation(Animation):
    """Frames of one simulated run of a planar mechanism (see the module notes).

    Parameters
    ----------
    netlist : Netlist
    time : array
        Simulated times (s).
    outputs : array
        ``(len(time), len(names))`` simulated outputs.
    names : sequence of str
        Output labels; must include :func:`position_variables`.
    inputs : array
        ``(len(time), ninputs)`` (unused: loads are not drawn).
    options : Options
        ``spacing`` and ``rod_scale`` do not apply (the drawing is to scale).
    """

    def __init__(
        self,
        netlist: Netlist,
        time: NDArray[np.float64],
        outputs: NDArray[np.float64],
        names: Sequence[str],
        inputs: NDArray[np.float64],
        options: Options,
    ) -> None:
        self.mechanism: Mechanism = mechanism_tree(netlist)
        self.title = netlist.title
        self.time = np.asarray(time, dtype=float)
        self.inputs = np.asarray(inputs, dtype=float)
        self.options = options
        col = {n.lower(): k for k, n in enumerate(names)}
        points = self.mechanism.points
        self.xy = np.stack(
            [outputs[:, [col[f"px({p})"] for p in points]], outputs[:, [col[f"py({p})"] for p in points]]],
            axis=2,
        )  # (time, point, 2)
        duration = float(self.time[-1] - self.time[0])
        count = math.floor(duration * options.fps / options.speed + 1e-9) + 1
        if count > MAX_FRAMES:
            raise UsageError(
                f"--animate: {count} frames; raise --speed or lower --fps (at most {MAX_FRAMES})"
            )
        wanted = self.time[0] + np.arange(count) * options.speed / options.fps
        index = np.clip(np.searchsorted(self.time, wanted), 1, max(self.time.size - 1, 1))
        earlier = np.abs(self.time[index - 1] - wanted) <= np.abs(
            self.time[np.minimum(index, self.time.size - 1)] - wanted
        )
        self.samples = np.where(earlier, index - 1, np.minimum(index, self.time.size - 1))

    def view(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1) (m): every point over the run, a margin, the frame's aspect."""
        finite = self.xy[np.all(np.isfinite(self.xy), axis=(1, 2))]
        if not finite.size:
            raise UsageError("--animate: the run has no finite positions to draw")
        lo, hi = finite.min(axis=(0, 1)), finite.max(axis=(0, 1))
        span = max(float(np.max(hi - lo)), 0.5)
        lo, hi = lo - 0.15 * span, hi + 0.15 * span
        w, h = self.options.size
        cx, cy = (lo + hi) / 2
        half_w, half_h = (hi - lo) / 2
        if half_w / half_h < w / h:
            half_w = half_h * w / h
        else:
            half_h = half_w * h / w
        return float(cx - half_w), float(cx + half_w), float(cy - half_h), float(cy + half_h)

    def draw(self, ax: Any, k: int) -> None:
        """Draw sample ``k`` on ``ax``."""
        x0, x1, y0, y1 = self._limits
        scale = x1 - x0
        ax.clear()
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        mech = self.mechanism
        pos = self.xy[k]
        size = 0.025 * scale
        for joint in mech.joints:
            if joint.kind == "slider":  # its track over the whole run
                track = self.xy[:, joint.point][np.all(np.isfinite(self.xy[:, joint.point]), axis=1)]
                a, b = track.min(axis=0), track.max(axis=0)
                d = np.array(joint.direction)
                pad = 2 * size * d
                ax.plot(
                    [a[0] - pad[0], b[0] + pad[0]],
                    [a[1] - pad[1], b[1] + pad[1]],
                    color="0.6",
                    lw=3,
                    zorder=1,
                )
            elif joint.kind == "fixed" and joint.card is not None:
                px, py = pos[joint.point]
                ax.fill(
                    [px, px - size, px + size],
                    [py, py - 1.6 * size, py - 1.6 * size],
                    color="0.5",
                    hatch="///",
                )
        damped = {frozenset((a, b)) for a, b, _ in mech.dampers}
        sprung = {frozenset((a, b)) for a, b, _, _ in mech.springs}
        for a, b, _, _ in mech.springs:  # beside a damper on the same ends: one each side
            shift = 1.2 * size if frozenset((a, b)) in damped else 0.0
            _zigzag2d(ax, *_shifted(pos[a], pos[b], shift), 0.6 * size)
        for a, b, _ in mech.dampers:
            shift = -1.2 * size if frozenset((a, b)) in sprung else 0.0
            _piston2d(ax, *_shifted(pos[a], pos[b], shift), 0.6 * size)
        for joint in mech.joints:
            if joint.kind == "link":
                (ax0, ay0), (bx, by) = pos[joint.parent], pos[joint.point]
                ax.plot([ax0, bx], [ay0, by], color="0.15", lw=2.5, zorder=3)
                ax.plot([ax0], [ay0], "o", color="white", mec="0.15", ms=5, zorder=3.5)  # under a bob
        heaviest = max((m for _, m, _ in mech.bodies), default=1.0) or 1.0
        sliding = {j.point: j for j in mech.joints if j.kind == "slider"}
        for point, m, _ in mech.bodies:
            px, py = pos[point]
            if point in sliding:  # a block along its track
                d = np.array(sliding[point].direction)
                n = np.array([-d[1], d[0]])
                half = 1.6 * size
                corners = [
                    (px, py) + s * half * d + t * 0.7 * half * n
                    for s, t in ((-1, -1), (1, -1), (1, 1), (-1, 1))
                ]
                ax.fill([c[0] for c in corners], [c[1] for c in corners], color="tab:blue", zorder=4)
            else:
                radius = 1.2 * size * math.sqrt(max(m, 0.0) / heaviest) + 0.3 * size
                ax.add_patch(_circle((px, py), radius))
        g = np.array(mech.gravity)
        if np.any(g):
            d = g / np.linalg.norm(g)
            centre = np.array([x1 - 0.06 * scale, y1 - 0.12 * (y1 - y0)])
            tail, head = centre - 0.04 * scale * d, centre + 0.04 * scale * d
            ax.annotate(
                "", xy=tuple(head), xytext=tuple(tail), arrowprops={"arrowstyle": "->", "color": "0.3"}
            )
            ax.text(centre[0] + 0.015 * scale, centre[1], "g", color="0.3", fontsize=9, va="center")
        ax.text(x0 + 0.02 * scale, y1 - 0.06 * (y1 - y0), f"t = {self.time[k]:.3f} s", fontsize=9)
        ax.text(x0 + 0.02 * scale, y0 + 0.03 * (y1 - y0), self.title[:90], fontsize=7, color="0.3")


def _shifted(
    a: NDArray[np.float64], b: NDArray[np.float64], shift: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The segment a–b moved sideways by ``shift`` (m)."""
    d = b - a
    length = float(np.hypot(*d))
    if not shift or not length > 0:
        return a, b
    n = np.array([-d[1], d[0]]) / length * shift
    return a + n, b + n


def _circle(center: tuple[float, float], radius: float) -> Any:
    from matplotlib.patches import Circle  # noqa: PLC0415 (deferred, matplotlib: optional plot extra)

    return Circle(center, radius, color="tab:red", zorder=4)


def _zigzag2d(ax: Any, a: NDArray[np.float64], b: NDArray[np.float64], amp: float) -> None:
    """A spring from a to b: straight ends and 11 teeth."""
    d = b - a
    length = float(np.hypot(*d))
    if not length > 0:
        return
    n = np.array([-d[1], d[0]]) / length
    s = [0.0, 0.15] + [0.15 + 0.7 * j / 12 for j in range(1, 12)] + [0.85, 1.0]
    off = [0.0, 0.0] + [amp if j % 2 else -amp for j in range(1, 12)] + [0.0, 0.0]
    pts = [a + si * d + oi * n for si, oi in zip(s, off, strict=True)]
    ax.plot([p[0] for p in pts], [p[1] for p in pts], color="0.15", lw=1.2, zorder=2)


def _piston2d(ax: Any, a: NDArray[np.float64], b: NDArray[np.float64], half: float) -> None:
    """A damper from a to b: a cylinder on a's side, a rod with a plate on b's."""
    d = b - a
    length = float(np.hypot(*d))
    if not length > 0:
        return
    n = np.array([-d[1], d[0]]) / length

    def seg(p: NDArray[np.float64], q: NDArray[np.float64], lw: float = 1.2) -> None:
        ax.plot([p[0], q[0]], [p[1], q[1]], color="0.15", lw=lw, zorder=2)

    c0, c1, plate = a + 0.2 * d, a + 0.6 * d, a + 0.5 * d
    seg(a, c0)
    seg(c0 + half * n, c1 + half * n)
    seg(c0 - half * n, c1 - half * n)
    seg(c0 - half * n, c0 + half * n)
    seg(plate - 0.75 * half * n, plate + 0.75 * half * n, 2.0)
    seg(plate, b)
