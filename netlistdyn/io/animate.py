"""Animations of mechanical netlists: a view of the simulation ``simulate`` reports.

Every frame shows the simulated outputs at one of the simulated times (the
nearest sample to ``k · speed / fps``, stamped with its own time): blocks at
``rest + x(node)``, rods at ``angle(rod)`` from their pivot, wheels of
rotational inertias turned by ``x(node)`` (their angle). Nothing is
re-simulated or interpolated.

Drawing conventions: masses are blocks on a track, springs zigzags and
dampers pistons between their nodes (a spring and a damper in parallel are
drawn one above the other), the frame (node 0) is a hatched wall, a rod is a
line from its pivot with its bob as a disc (upright rods above the block,
hanging ones below), an inertia is a wheel with a spoke. Geometry the netlist
does not give is chosen automatically: neighbouring nodes ``spacing`` apart
(enough that blocks never overlap over the run), rods drawn at their length
times ``rod_scale`` (1 unless the rods would dwarf the chain or vanish beside
it). Both can be overridden.
"""

from __future__ import annotations

import io
import itertools
import math
import os
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from netlistdyn.analysis.validity import SMALL_ANGLE_LIMIT
from netlistdyn.base.atomic import write_bytes
from netlistdyn.base.errors import UsageError
from netlistdyn.circuit.netlist import GROUND, Netlist

BLOCK_COLOUR = "#3d6fa8"
BOB_COLOUR = "#c8322b"
WHEEL_COLOUR = "#6b8e23"
TRANSLATIONAL = {"MASS", "FORCE", "ROD"}
ROTATIONAL = {"INERTIA", "TORQUE", "GEAR", "MOTOR"}
#: Most frames one animation may have.
MAX_FRAMES = 5_000
_UNITS = {"FORCE": "N", "TORQUE": "N·m", "VELOCITY": "m/s"}


@dataclass(frozen=True)
class Rod:
    """A pendulum rod: pivot node, bob node, length (m), upright or hanging."""

    name: str
    pivot: str
    bob: str
    length: float
    inverted: bool


@dataclass(frozen=True)
class Link:
    """A spring or damper between two nodes (node 0: the frame)."""

    kind: str
    name: str
    a: str
    b: str


@dataclass
class Scene:
    """What to draw and where, derived from the netlist.

    Attributes
    ----------
    line : list of str
        Translational nodes on the track, left to right (rod bobs excluded).
    wheels : list of str
        Rotational nodes, left to right.
    rods : list of Rod
    links : list of Link
    masses : dict
        Node -> mass element names.
    inputs : list of tuple
        (input name, unit) of every source.
    spacing : float
        Rest distance between neighbouring nodes (m, drawing units).
    rod_scale : float
        Drawn rod length / true length.
    """

    line: list[str] = field(default_factory=list)
    wheels: list[str] = field(default_factory=list)
    rods: list[Rod] = field(default_factory=list)
    links: list[Link] = field(default_factory=list)
    masses: dict[str, list[str]] = field(default_factory=dict)
    inputs: list[tuple[str, str]] = field(default_factory=list)
    gears: list[tuple[str, str, str, float]] = field(default_factory=list)
    spacing: float = 1.0
    rod_scale: float = 1.0


def is_mechanical(netlist: Netlist) -> bool:
    """True when the netlist has a mass, inertia or rod to draw."""
    return any(e.keyword in ("MASS", "INERTIA", "ROD") for e in netlist.elements)


def scene_of(netlist: Netlist) -> Scene:
    """Classify the mechanical nodes and elements of a netlist.

    Raises
    ------
    UsageError
        For a netlist with nothing mechanical to draw.
    """
    if not is_mechanical(netlist):
        raise UsageError(
            "--animate: this netlist has no mechanical element (MASS, INERTIA, ROD) to animate; "
            "--plot draws its outputs"
        )
    scene = Scene()
    rotational: set[str] = set()
    translational: set[str] = set()
    for e in netlist.elements:
        kw = e.keyword or ""
        nodes = [n for n in e.nodes if n != GROUND]
        if kw == "MOTOR":
            rotational.add(e.nodes[2])
        elif kw in ROTATIONAL or kw == "INERTIA":
            rotational.update(nodes)
        elif kw in TRANSLATIONAL:
            translational.update(nodes)
        if kw in ("MASS", "INERTIA"):
            scene.masses.setdefault(e.nodes[0], []).append(e.name)
        elif kw == "ROD":
            assert e.rod is not None
            scene.rods.append(Rod(e.name, e.nodes[0], e.nodes[1], e.rod.length, e.rod.inverted))
        elif kw in ("SPRING", "DAMPER"):
            scene.links.append(Link(kw, e.name, e.nodes[0], e.nodes[1]))
        elif kw == "GEAR":
            scene.gears.append((e.name, e.nodes[0], e.nodes[2], e.value))
        if e.is_source:
            scene.inputs.append((e.name, _UNITS.get(kw, "A" if e.kind.name == "ISOURCE" else "V")))
    # Springs and dampers belong to the side of the nodes they join.
    for link in scene.links:
        ends = {link.a, link.b} - {GROUND}
        (rotational if ends & rotational else translational).update(ends)
    bobs = {r.bob for r in scene.rods}
    scene.line = _order([n for n in _in_order(netlist, translational) if n not in bobs], scene.links)
    scene.wheels = _order(_in_order(netlist, rotational), scene.links, scene.gears)
    return scene


def _in_order(netlist: Netlist, nodes: set[str]) -> list[str]:
    return [n for n in netlist.nodes if n in nodes]


def _order(
    nodes: list[str], links: Sequence[Link], gears: Sequence[tuple[str, str, str, float]] = ()
) -> list[str]:
    """Nodes tied to the frame first, then along springs, dampers and gears (breadth first)."""
    neighbours: dict[str, list[str]] = {n: [] for n in [*nodes, GROUND]}
    pairs = [(link.a, link.b) for link in links] + [(g[1], g[2]) for g in gears]
    for a, b in pairs:
        if a in neighbours and b in neighbours:
            neighbours[a].append(b)
            neighbours[b].append(a)
    order: list[str] = []
    frontier = [GROUND]
    seen = {GROUND}
    while True:
        while frontier:
            nxt = []
            for n in frontier:
                for m in neighbours[n]:
                    if m not in seen:
                        seen.add(m)
                        order.append(m)
                        nxt.append(m)
            frontier = nxt
        rest = [n for n in nodes if n not in seen]
        if not rest:
            return order
        seen.add(rest[0])
        order.append(rest[0])
        frontier = [rest[0]]


def position_variables(netlist: Netlist) -> list[str]:
    """The outputs an animation needs: x(node) of track nodes and wheels, angle(rod) of rods."""
    scene = scene_of(netlist)
    return [*(f"x({n})" for n in [*scene.line, *scene.wheels]), *(f"angle({r.name})" for r in scene.rods)]


@dataclass(frozen=True)
class Options:
    """Animation settings.

    Attributes
    ----------
    fps : float
        Frames per second of the file.
    speed : float
        Simulated seconds per second of animation.
    size : tuple of int
        Width and height in pixels.
    spacing, rod_scale : float, optional
        Geometry overrides (see the module notes).
    """

    fps: float = 25.0
    speed: float = 1.0
    size: tuple[int, int] = (640, 360)
    spacing: float | None = None
    rod_scale: float | None = None


def parse_geometry(items: Sequence[str]) -> dict[str, float]:
    """``("spacing=2", "rod_scale=0.5")`` -> dict; refuses unknown keys and non-positive values."""
    out = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip().lower().replace("-", "_")
        try:
            value = float(text) if sep else math.nan
        except ValueError:
            value = math.nan
        if key not in ("spacing", "rod_scale") or not value > 0 or not math.isfinite(value):
            raise UsageError(f"--geometry {item!r}: expected spacing=M or rod_scale=F with a positive number")
        out[key] = value
    return out


def animation_options(path: str, fps: float, speed: float, size: str, geometry: Sequence[str]) -> Options:
    """Check the ``--animate`` options of the command line.

    Raises
    ------
    UsageError
    """
    if Path(path).suffix.lower() not in (".gif", ".mp4"):
        raise UsageError(f"--animate {path}: use a .gif or .mp4 file name")
    if Path(path).suffix.lower() == ".mp4" and shutil.which("ffmpeg") is None:
        raise UsageError("--animate .mp4 needs ffmpeg (apt-get install ffmpeg); a .gif needs nothing else")
    if not (0 < fps <= 100 and math.isfinite(fps)) or not (speed > 0 and math.isfinite(speed)):
        raise UsageError("--fps must be in (0, 100] and --speed positive")
    w, sep, h = size.lower().partition("x")
    if not (sep and w.isdigit() and h.isdigit() and 64 <= int(w) <= 4000 and 64 <= int(h) <= 4000):
        raise UsageError(f"--frame-size {size!r}: expected WxH in pixels, e.g. 640x360 (64..4000)")
    g = parse_geometry(geometry)
    return Options(fps, speed, (int(w), int(h)), g.get("spacing"), g.get("rod_scale"))


class Animation:
    """Frames of one simulated run.

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
        ``(len(time), ninputs)`` input values at the same times.
    options : Options
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
        self.scene = scene_of(netlist)
        self.title = netlist.title
        self.time = np.asarray(time, dtype=float)
        self.inputs = np.asarray(inputs, dtype=float)
        self.options = options
        col = {n: k for k, n in enumerate(names)}
        self.x = {n: outputs[:, col[f"x({n})"]] for n in [*self.scene.line, *self.scene.wheels]}
        self.angle = {r.name: outputs[:, col[f"angle({r.name})"]] for r in self.scene.rods}
        self._choose_geometry()
        duration = float(self.time[-1] - self.time[0])
        count = math.floor(duration * options.fps / options.speed + 1e-9) + 1
        if count > MAX_FRAMES:
            raise UsageError(
                f"--animate: {count} frames; raise --speed or lower --fps (at most {MAX_FRAMES})"
            )
        wanted = self.time[0] + np.arange(count) * options.speed / options.fps
        self.samples = np.clip(
            np.searchsorted(self.time, wanted - 1e-12 * max(duration, 1.0)), 0, self.time.size - 1
        )
        nearer = np.abs(self.time[np.maximum(self.samples - 1, 0)] - wanted) < np.abs(
            self.time[self.samples] - wanted
        )
        self.samples = np.where(nearer, np.maximum(self.samples - 1, 0), self.samples)

    # --- geometry ------------------------------------------------------------------

    def _finite_peak(self, values: NDArray[np.float64]) -> float:
        values = values[np.isfinite(values)]
        return float(np.max(np.abs(values))) if values.size else 0.0

    def _choose_geometry(self) -> None:
        scene, opts = self.scene, self.options
        # Neighbouring blocks never overlap: spacing ≥ block + largest relative motion.
        relative = [0.0]
        line = scene.line
        for a, b in itertools.pairwise(line):
            relative.append(self._finite_peak(self.x[a] - self.x[b]))
        if line:
            relative.append(self._finite_peak(self.x[line[0]]))
        chain = self._longest_chain() if scene.rods else 0.0
        motion = 1.6 * min(max(relative), 1e6)
        if not chain:
            base = motion
        elif motion > 3 * chain or motion == 0:
            # Rods alone, or motion that dwarfs them (an unstable run): size by the rods and
            # let what runs away leave the view (the frame says so).
            base = 1.2 * chain
        else:
            # Motion readable first; rods up to half a spacing each way unless that would
            # shrink the motion below a quarter of the spacing (then the rods are scaled).
            base = max(motion, min(0.5 * chain, 4 * motion))
        spacing = opts.spacing or (base if base > 0 else 1.0)
        scene.spacing = spacing
        if opts.rod_scale is not None:
            scene.rod_scale = opts.rod_scale
        elif chain:
            scene.rod_scale = 1.0 if 0.4 * spacing <= chain <= 4 * spacing else 1.5 * spacing / chain
        drawn_chain = chain * scene.rod_scale
        self.block = min(max(0.4 * spacing, 0.2 * drawn_chain), 0.8 * spacing) if line else 0.0
        self.radius = 0.3 * spacing
        self.bob_radius = (
            0.09 * spacing if not chain else max(min(0.09 * spacing, 0.12 * drawn_chain), 0.05 * drawn_chain)
        )

    def _longest_chain(self) -> float:
        below: dict[str, list[Rod]] = {r.pivot: [] for r in self.scene.rods}
        for r in self.scene.rods:
            below.setdefault(r.pivot, []).append(r)

        def depth(node: str, trail: int = 0) -> float:
            if trail > len(self.scene.rods):
                return 0.0
            return max((r.length + depth(r.bob, trail + 1) for r in below.get(node, [])), default=0.0)

        return max(depth(r.pivot) for r in self.scene.rods)

    def rest(self, node: str) -> float:
        """Rest position (drawing x) of a track node or wheel."""
        order = self.scene.line if node in self.scene.line else self.scene.wheels
        return self.scene.spacing * (order.index(node) + 1)

    def layout(self, k: int) -> dict[str, tuple[float, float]]:
        """Drawn positions at sample ``k``: block and bob centres, wheel spoke tips.

        Keys are node names; a wheel's entry is (centre x, spoke angle in rad).
        """
        out: dict[str, tuple[float, float]] = {}
        for n in self.scene.line:
            out[n] = (self.rest(n) + float(self.x[n][k]), 0.0)
        for n in self.scene.wheels:
            out[n] = (self.rest(n), float(self.x[n][k]))
        out[GROUND] = (self.scene.spacing, 0.0)  # a rod pivoted on the frame hangs from here
        pending = list(self.scene.rods)
        while pending:
            progressed = False
            for r in list(pending):
                if r.pivot not in out:
                    continue
                px, py = self._pivot(r, out[r.pivot])
                theta = float(self.angle[r.name][k])
                length = r.length * self.scene.rod_scale
                up = 1.0 if r.inverted else -1.0
                out[r.bob] = (px + length * math.sin(theta), py + up * length * math.cos(theta))
                pending.remove(r)
                progressed = True
            if not progressed:
                break
        return out

    def _pivot(self, rod: Rod, at: tuple[float, float]) -> tuple[float, float]:
        """Where a rod is drawn from: the top (upright) or bottom (hanging) of its block.

        Several rods on one block are spread along its side so that they do not
        overlap (two pendula on a cart); a single rod starts at the middle.
        """
        if rod.pivot in self.scene.line:
            half = self.block / 2
            siblings = [r for r in self.scene.rods if r.pivot == rod.pivot and r.inverted == rod.inverted]
            j, count = siblings.index(rod), len(siblings)
            shift = 0.0 if count == 1 else (j / (count - 1) - 0.5) * 0.7 * self.block
            return (at[0] + shift, at[1] + (half if rod.inverted else -half))
        return at

    def view(self) -> tuple[float, float, float, float]:
        """Axis limits covering the rest geometry and the motion (up to 3 spacings beyond it)."""
        s = self.scene.spacing
        n = max(len(self.scene.line), len(self.scene.wheels), 1)
        left, right = -0.4 * s, s * (n + 1)
        lows, highs = [left], [right]
        for node in self.scene.line:
            path = self.rest(node) + self.x[node][np.isfinite(self.x[node])]
            if path.size:
                lows.append(max(float(path.min()) - self.block, -3 * s))
                highs.append(min(float(path.max()) + self.block, (n + 3) * s))
        chain = self._longest_chain() * self.scene.rod_scale if self.scene.rods else 0.0
        up = any(r.inverted for r in self.scene.rods)
        down = any(not r.inverted for r in self.scene.rods)
        lows[0] = min(lows) - (chain if self.scene.rods else 0.0)
        highs[0] = max(highs) + (chain if self.scene.rods else 0.0)
        top = max(self.block, self.radius) * 0.5 + (chain + self.bob_radius if up else 0.0) + 0.35 * s
        bottom = -max(self.block, self.radius) * 0.5 - (chain + self.bob_radius if down else 0.0) - 0.3 * s
        return min(lows), max(highs), bottom, top

    # --- drawing -------------------------------------------------------------------

    def draw(self, ax: Any, k: int) -> None:
        """Draw sample ``k`` into a matplotlib axes (cleared first)."""
        from matplotlib.patches import Circle, Rectangle  # noqa: PLC0415 (deferred, matplotlib: optional plot extra)

        ax.cla()
        x0, x1, y0, y1 = self._limits
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        ax.axis("off")
        pos = self.layout(k)
        s, h = self.scene.spacing, self.block
        if self.scene.line:
            track = -h / 2
            ax.plot([x0, x1], [track, track], color="0.35", lw=1.2, zorder=1)
            if not any(not r.inverted and r.pivot in self.scene.line for r in self.scene.rods):
                ax.add_patch(
                    Rectangle(
                        (x0, track - 0.08 * s),
                        x1 - x0,
                        0.08 * s,
                        hatch="////",
                        fill=False,
                        lw=0,
                        color="0.55",
                    )
                )
        grounded = any(GROUND in (link.a, link.b) for link in self.scene.links)
        if grounded:
            wall = 0.0
            hh = max(h, 2 * self.radius) * 0.9
            ax.add_patch(
                Rectangle(
                    (wall - 0.12 * s, -hh / 2 - (h / 2 if self.scene.line else 0) * 0),
                    0.12 * s,
                    hh,
                    hatch="////",
                    fill=False,
                    color="0.3",
                    lw=1.0,
                )
            )
            ax.plot([wall, wall], [-hh / 2, hh / 2], color="0.2", lw=2)
        self._draw_links(ax, pos)
        for n in self.scene.line:
            cx, cy = pos[n]
            ax.add_patch(Rectangle((cx - h / 2, cy - h / 2), h, h, color=BLOCK_COLOUR, zorder=3))
            ax.text(
                cx,
                cy,
                "\n".join(self.scene.masses.get(n, [n])),
                ha="center",
                va="center",
                color="white",
                fontsize=8,
                zorder=4,
            )
        for n in self.scene.wheels:
            cx, theta = pos[n]
            ax.add_patch(Circle((cx, 0), self.radius, color=WHEEL_COLOUR, zorder=3))
            tip = (cx + self.radius * math.sin(theta), self.radius * math.cos(theta))
            ax.plot([cx, tip[0]], [0, tip[1]], color="white", lw=2.5, zorder=4)
            ax.text(
                cx,
                -self.radius - 0.08 * s,
                ", ".join(self.scene.masses.get(n, [n])),
                ha="center",
                va="top",
                fontsize=8,
            )
        for name, a, b, ratio in self.scene.gears:
            if a in pos and b in pos:
                ax.text(
                    (pos[a][0] + pos[b][0]) / 2,
                    self.radius * 0.9,
                    f"{name} {ratio:g}:1",
                    ha="center",
                    fontsize=8,
                )
                ax.plot(
                    [pos[a][0] + self.radius, pos[b][0] - self.radius], [0, 0], color="0.2", lw=3, zorder=2
                )
        for r in self.scene.rods:
            if r.pivot == GROUND:
                px, py = pos[GROUND]
                side = -1.0 if r.inverted else 1.0
                ax.add_patch(
                    Rectangle(
                        (px - 0.3 * s, py if side > 0 else py - 0.08 * s),
                        0.6 * s,
                        0.08 * s,
                        hatch="////",
                        fill=False,
                        color="0.3",
                        lw=1.0,
                    )
                )
            if r.bob not in pos:
                continue
            px, py = self._pivot(r, pos[r.pivot])
            bx, by = pos[r.bob]
            ax.plot([px, bx], [py, by], color="0.15", lw=2, zorder=5, solid_capstyle="round")
            ax.add_patch(Circle((px, py), 0.025 * s, color="0.15", zorder=6))
            ax.add_patch(Circle((bx, by), self.bob_radius, color=BOB_COLOUR, zorder=6))
        self._draw_labels(ax, k)

    def _draw_links(self, ax: Any, pos: dict[str, tuple[float, float]]) -> None:
        pairs: dict[frozenset[str], list[Link]] = {}
        for link in self.scene.links:
            pairs.setdefault(frozenset((link.a, link.b)), []).append(link)
        for group in pairs.values():
            for j, link in enumerate(group):
                offset = (
                    0.0
                    if len(group) == 1
                    else (0.22 - 0.44 * j / (len(group) - 1)) * max(self.block, self.radius)
                )
                ends = sorted((self._anchor(link.a, pos), self._anchor(link.b, pos)), key=lambda p: p[0])
                (xa, ha), (xb, hb) = ends
                xa, xb = xa + ha, xb - hb
                if link.kind == "SPRING":
                    _zigzag(ax, xa, xb, offset, 0.08 * self.scene.spacing)
                    if link.a in self.scene.wheels or link.b in self.scene.wheels:
                        twist = pos.get(link.a, (0.0, 0.0))[1] - pos.get(link.b, (0.0, 0.0))[1]
                        ax.text(
                            (xa + xb) / 2,
                            -self.radius - 0.22 * self.scene.spacing,
                            f"{link.name} twist\n{twist:.3g} rad",
                            ha="center",
                            va="top",
                            fontsize=7,
                        )
                else:
                    _piston(ax, xa, xb, offset, 0.07 * self.scene.spacing)

    def _anchor(self, node: str, pos: dict[str, tuple[float, float]]) -> tuple[float, float]:
        """(x, half-width) where a link attaches to a node: the wall, a block's side or a wheel's rim."""
        if node == GROUND:
            return (0.0, 0.0)
        if node in self.scene.line:
            return (pos[node][0], self.block / 2)
        if node in self.scene.wheels:
            return (pos[node][0], self.radius)
        return (pos.get(node, (0.0, 0.0))[0], 0.0)

    def _draw_labels(self, ax: Any, k: int) -> None:
        t = self.time[k]
        parts = [f"t = {t:.3f} s"]
        for j, (name, unit) in enumerate(self.scene.inputs):
            parts.append(f"{name} = {self.inputs[k, j]:.4g} {unit}")
        figure = ax.figure.transFigure
        title = self.title if len(self.title) <= 70 else self.title[:69].rstrip() + "…"
        ax.text(0.01, 0.99, title, transform=figure, va="top", fontsize=7, color="0.4")
        ax.text(0.01, 0.93, "   ".join(parts), transform=figure, va="top", fontsize=9, family="monospace")
        notes = []
        if self.scene.rod_scale != 1.0:
            notes.append(f"rods drawn x{self.scene.rod_scale:.3g}")
        if any(abs(self.angle[r.name][k]) > SMALL_ANGLE_LIMIT for r in self.scene.rods):
            notes.append("rod angle > 0.14 rad: linear model outside its range")
        off = [
            n
            for n in self.scene.line
            if not (self._limits[0] <= self.rest(n) + self.x[n][k] <= self._limits[1])
        ]
        if off:
            notes.append("off screen: " + ", ".join(f"x({n}) = {self.x[n][k]:.3g} m" for n in off))
            x0, x1 = self._limits[:2]
            for n in off:
                right = self.rest(n) + self.x[n][k] > x1
                ax.text(
                    x1 if right else x0,
                    0.0,
                    f"{n} →" if right else f"← {n}",
                    ha="right" if right else "left",
                    va="center",
                    fontsize=10,
                    color=BLOCK_COLOUR,
                )
        if notes:
            ax.text(
                0.01, 0.02, "; ".join(notes), transform=ax.figure.transFigure, fontsize=8, color="#a02020"
            )

    @property
    def _limits(self) -> tuple[float, float, float, float]:
        if not hasattr(self, "_cached_limits"):
            self._cached_limits = self.view()
        return self._cached_limits

    def frames(self) -> NDArray[np.intp]:
        """The sample index shown in each frame."""
        return self.samples

    def render(self, k: int) -> NDArray[np.uint8]:
        """Frame ``k`` (of :meth:`frames`) as an RGB array ``(height, width, 3)``."""
        _fig, ax, canvas = self._figure()
        self.draw(ax, int(self.samples[k]))
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()

    def _figure(self) -> tuple[Any, Any, Any]:
        if not hasattr(self, "_fig"):
            from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415 (deferred, matplotlib: optional plot extra)
            from matplotlib.figure import Figure  # noqa: PLC0415 (deferred, matplotlib: optional plot extra)

            w, h = self.options.size
            fig = Figure(figsize=(w / 100, h / 100), dpi=100)
            ax = fig.add_axes((0.01, 0.01, 0.98, 0.98))
            self._fig = (fig, ax, FigureCanvasAgg(fig))
        return self._fig

    def to_data(self, row: float, col: float) -> tuple[float, float]:
        """Pixel (row, column) of a rendered frame -> drawing coordinates."""
        _fig, ax, _ = self._figure()
        height = self.options.size[1]
        inverse = ax.transData.inverted()
        x, y = inverse.transform((col + 0.5, height - row - 0.5))
        return float(x), float(y)

    def save(self, path: str) -> int:
        """Write every frame to a .gif (Pillow) or .mp4 (ffmpeg); returns the frame count."""
        suffix = Path(path).suffix.lower()
        if suffix == ".gif":
            from PIL import Image  # noqa: PLC0415 (deferred, Pillow: only to write a GIF)

            def frame(k: int) -> Any:
                rgb = Image.fromarray(self.render(k))
                return rgb.convert("P", palette=Image.Palette.ADAPTIVE, colors=64)

            # One frame in memory at a time (Pillow consumes the generator while encoding).
            rest = (frame(k) for k in range(1, len(self.samples)))
            buffer = io.BytesIO()
            frame(0).save(
                buffer,
                format="GIF",
                save_all=True,
                append_images=rest,
                duration=max(round(1000 / self.options.fps), 20),
                loop=0,
                disposal=1,
            )
            write_bytes(path, buffer.getvalue())
        elif suffix == ".mp4":
            self._save_mp4(path)
        else:
            raise UsageError(f"--animate {path}: use a .gif or .mp4 file name")
        return len(self.samples)

    def _save_mp4(self, path: str) -> None:
        ffmpeg = shutil.which("ffmpeg")
        if ffmpeg is None:
            raise UsageError(
                "--animate .mp4 needs ffmpeg (apt-get install ffmpeg); a .gif needs nothing else"
            )
        w, h = self.options.size
        target = Path(path)
        fd, tmp = tempfile.mkstemp(dir=target.parent or Path("."), prefix=f".{target.name}.", suffix=".mp4")
        os.close(fd)
        command = [
            ffmpeg,
            "-y",
            "-loglevel",
            "error",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
            "-s",
            f"{w}x{h}",
        ]
        command += [
            "-r",
            f"{self.options.fps:g}",
            "-i",
            "-",
            "-pix_fmt",
            "yuv420p",
            "-vf",
            "pad=ceil(iw/2)*2:ceil(ih/2)*2",
            tmp,
        ]
        try:
            with subprocess.Popen(command, stdin=subprocess.PIPE) as proc:
                assert proc.stdin is not None
                for k in range(len(self.samples)):
                    proc.stdin.write(self.render(k).tobytes())
                proc.stdin.close()
                if proc.wait() != 0:
                    raise UsageError(f"--animate {path}: ffmpeg failed")
            os.replace(tmp, target)
        finally:
            Path(tmp).unlink(missing_ok=True)


def _zigzag(ax: Any, xa: float, xb: float, y: float, amp: float) -> None:
    """A spring: straight ends and 6 teeth between xa and xb at height y."""
    length = xb - xa
    lead = 0.15 * length
    xs = [xa, xa + lead]
    ys = [y, y]
    teeth = 12
    for j in range(1, teeth):
        xs.append(xa + lead + (length - 2 * lead) * j / teeth)
        ys.append(y + (amp if j % 2 else -amp))
    xs += [xb - lead, xb]
    ys += [y, y]
    ax.plot(xs, ys, color="0.15", lw=1.2, zorder=2)


def _piston(ax: Any, xa: float, xb: float, y: float, half: float) -> None:
    """A damper: a cylinder on one side, a rod with a plate on the other."""
    length = xb - xa
    cyl0, cyl1 = xa + 0.2 * length, xa + 0.6 * length
    plate = xa + 0.5 * length
    ax.plot([xa, cyl0], [y, y], color="0.15", lw=1.2, zorder=2)
    ax.plot([cyl0, cyl1], [y + half, y + half], color="0.15", lw=1.2, zorder=2)
    ax.plot([cyl0, cyl1], [y - half, y - half], color="0.15", lw=1.2, zorder=2)
    ax.plot([cyl0, cyl0], [y - half, y + half], color="0.15", lw=1.2, zorder=2)
    ax.plot([plate, plate], [y - 0.75 * half, y + 0.75 * half], color="0.15", lw=2, zorder=2)
    ax.plot([plate, xb], [y, y], color="0.15", lw=1.2, zorder=2)
