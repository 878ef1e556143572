"""Independent reference built from ngspice's own reading of a netlist file.

netlistdyn's parser is the thing under test, so this module never imports it.
For one netlist file it

1. runs ngspice 39 in pipe mode on the file (``.control`` blocks removed, so
   that the file's own analyses do not run) and asks for ``listing e``: the
   deck after ngspice has expanded subcircuits, parameters and expressions;
2. reads that flat listing with its own small reader (element letter, nodes,
   values with SPICE suffixes) and stamps a modified-nodal-analysis pencil
   ``(G + sC) z = Bu u`` (node voltages and the currents of V, L, E, H);
3. proves that reading right against ngspice itself: every independent source
   is given its own DC value and AC magnitude with ``alter``, ngspice runs
   ``op`` and ``ac`` at twelve frequencies, and the pencil must reproduce every
   node voltage and branch current it prints (relative 1e-6);
4. compares netlistdyn's compiled model with the pencil: the eigenvalues of A
   against the pencil's finite generalized eigenvalues, and the transfer
   matrix C(sI − A)⁻¹B + D + sD1 at three complex frequencies, both to 1e-6.

``classify(path)`` returns one :class:`Outcome`: ``agree``, ``refused`` (with
netlistdyn's one-line message), ``wrong`` (a number differs, or netlistdyn
compiled a file whose ngspice reading contains a nonlinear device), or
``no-reference`` (ngspice cannot read the file, or the listing holds a
construct this reader does not model).
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.optimize

#: Relative agreement demanded between the pencil and ngspice's op/ac output.
#: ngspice solves the same linear system with sparse LU in double precision and
#: writes 16 significant digits, so 1e-6 leaves ample room for rounding only.
NGSPICE_RTOL = 1e-6
#: Relative agreement demanded between netlistdyn and the pencil (issue #10).
MODEL_RTOL = 1e-6
#: Eigenvalues below this fraction of the spectral radius are compared
#: absolutely at that scale: QZ/shift-invert backward error is ~1e-16 of the
#: largest, so a zero eigenvalue is only known to ~1e-12 ρ.
ZERO_FLOOR = 1e-9
#: Seconds allowed for one ngspice run.
TIMEOUT = 20.0
#: Largest pencil handled (dense eigenvalues of the shift-inverted pencil; a
#: corpus file stays small so that each test takes well under a second).
MAX_UNKNOWNS = 400
#: Frequencies (Hz) of the ngspice ``ac`` check: one per decade, off round numbers.
AC_FREQUENCIES = tuple(1.23 * 10.0**k for k in range(-2, 10))

_SUFFIXES = (
    ("meg", 1e6),
    ("mil", 25.4e-6),
    ("t", 1e12),
    ("g", 1e9),
    ("k", 1e3),
    ("m", 1e-3),
    ("u", 1e-6),
    ("\u00b5", 1e-6),
    ("\u03bc", 1e-6),
    ("n", 1e-9),
    ("p", 1e-12),
    ("f", 1e-15),
)  # no "a": ngspice 39 reads 1a as 1 (measured: R1 1 0 1a → @r1[resistance] = 1)
_NUMBER = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+)(?:e[+-]?\d+)?)(.*)$", re.IGNORECASE)
_LISTING_LINE = re.compile(r"^\s*(\d+)\s*:\s(.*)$")
LINEAR_LETTERS = frozenset("rclviefghk")


class ReferenceUnavailable(Exception):
    """ngspice's reading cannot be turned into a checked reference."""


def spice_value(token: str) -> float:
    """A SPICE number as ngspice writes it in an expanded listing (``1k``, ``2.5e-3``)."""
    match = _NUMBER.match(token.strip())
    if not match:
        raise ReferenceUnavailable(f"not a number in ngspice's listing: {token!r}")
    value = float(match.group(1))
    rest = match.group(2).lower()
    for suffix, scale in _SUFFIXES:
        if rest.startswith(suffix):
            return value * scale
    return value


@dataclass(frozen=True)
class RefElement:
    """One element of ngspice's expanded listing."""

    name: str  # as ngspice prints it, lower case (``r.x1.r1``)
    letter: str
    nodes: tuple[str, ...]
    value: float = 0.0  # Ω, F, H, gain, k; a V source's port resistance
    control: tuple[str, ...] = ()


@dataclass
class Reading:
    """ngspice's expanded deck, read into elements."""

    elements: list[RefElement]
    listing: list[str]
    nonlinear: list[str] = field(default_factory=list)


@dataclass
class Pencil:
    """MNA pencil of the listing: (G + sC) z = Bu u."""

    G: np.ndarray
    C: np.ndarray
    Bu: np.ndarray
    nodes: list[str]
    branches: list[str]
    sources: list[str]

    def solve(self, s: complex, u: np.ndarray) -> np.ndarray:
        return np.linalg.solve(self.G + s * self.C, self.Bu @ u)

    def node_rows(self, names: list[str]) -> np.ndarray:
        rows = np.zeros((len(names), self.G.shape[0]))
        for i, name in enumerate(names):
            rows[i, self.nodes.index(name)] = 1.0
        return rows


# ---------------------------------------------------------------- ngspice runs


def ngspice_available() -> bool:
    return shutil.which("ngspice") is not None


def _without_control(text: str, drop: tuple[str, ...] = ()) -> str:
    kept, inside = [], False
    for line in text.splitlines():
        word = line.strip().lower()
        if drop and word.startswith(drop):
            continue
        if word.startswith(".control"):
            inside = True
            continue
        if inside:
            if word.startswith(".endc"):
                inside = False
            continue
        kept.append(line)
    return "\n".join(kept) + "\n"


def _run(path: Path, commands: list[str], workdir: Path) -> str:
    """Run ngspice in pipe mode on ``path`` and return what it printed."""
    script = "\n".join(["set width=4000", *commands, "quit", ""])
    proc = subprocess.run(
        ["ngspice", "-n", "-p", str(path)],
        input=script.encode(),
        capture_output=True,
        timeout=TIMEOUT,
        cwd=workdir,
    )
    return proc.stdout.decode("utf-8", "replace") + proc.stderr.decode("utf-8", "replace")


def _deck(path: Path, workdir: Path, drop: tuple[str, ...] = ()) -> Path:
    """The file as ngspice is given it: unchanged, or a copy without ``.control``
    blocks and without the lines starting with one of ``drop`` (directives of
    another simulator that ngspice 39 refuses, e.g. LTspice's ``.backanno``;
    the manifest names them per file)."""
    raw = path.read_bytes()
    text = raw.decode("utf-8", "replace")
    if not drop and not re.search(r"^\s*\.control", text, re.IGNORECASE | re.MULTILINE):
        return path
    copy = workdir / path.name
    copy.write_bytes(_without_control(raw.decode("latin-1"), drop).encode("latin-1"))
    return copy


def read_listing(output: str) -> list[str]:
    lines = []
    for line in output.splitlines():
        match = _LISTING_LINE.match(line)
        if match and match.group(1) != "1":  # line 1 is the title
            lines.append(match.group(2).strip())
    if not lines:
        first = next((ln for ln in output.splitlines() if "rror" in ln), output.strip()[:200])
        raise ReferenceUnavailable(f"ngspice printed no listing: {first.strip()}")
    return lines


def _tokens(text: str) -> list[str]:
    return text.replace("(", " ").replace(")", " ").replace(",", " ").split()


def _keyword_values(tokens: list[str]) -> tuple[list[str], dict[str, str]]:
    """Split ``['1k', 'm', '=', '2']`` / ``['m=2']`` into positionals and keywords."""
    joined = " ".join(tokens).replace(" =", "=").replace("= ", "=")
    positional, keywords = [], {}
    for tok in joined.split():
        if "=" in tok:
            key, _, val = tok.partition("=")
            keywords[key.lower()] = val
        else:
            positional.append(tok)
    return positional, keywords


_POLY_MODEL = re.compile(r"^\.model\s+(\S+)\s+spice2poly\s+coef\s*=\s*\[([^\]]*)\]")
_POLY_DEVICE = re.compile(r"^(a\$poly\$\S+)\s+%(vd|vnam)\s*\[([^\]]*)\]\s*%(vd|id)\s*\(([^)]*)\)\s*(\S+)$")


def _linear_poly(text: str, models: dict[str, list[float]]) -> list[RefElement] | None:
    """ngspice's code model for a SPICE2 ``POLY`` source, as controlled sources when it is linear.

    ngspice turns ``E/F/G/H ... POLY(n) ...`` into ``a$poly$NAME %vd|%vnam [controls] %vd|%id
    (out+ out-) model`` with ``.model model spice2poly coef = [p0 p1 ...]``. A first-order
    polynomial without a constant is n controlled sources (a voltage output: in series through
    internal nodes ``NAME.nK``; a current output: in parallel). None when the line is no such device
    or the polynomial is nonlinear; a constant p0 has no place in the pencil (refused).
    """
    match = _POLY_DEVICE.match(text)
    if match is None or match.group(6) not in models:
        return None
    name, inputs, controls, output, outs, model = match.groups()
    controls_list = controls.split()
    n = len(controls_list) // 2 if inputs == "vd" else len(controls_list)
    coef = models[model]
    if any(c != 0 for c in coef[n + 1 :]):
        return None
    if coef and coef[0] != 0:
        raise ReferenceUnavailable(f"{name}: POLY with a constant term {coef[0]:g}")
    gains = (coef[1 : n + 1] + [0.0] * n)[:n]
    plus, minus = outs.split()
    letter = {("vd", "vd"): "e", ("vd", "id"): "g", ("vnam", "vd"): "h", ("vnam", "id"): "f"}[
        (inputs, output)
    ]
    chain = [plus] + [f"{name}.n{k}" for k in range(1, n)] + [minus]
    out: list[RefElement] = []
    for k, gain in enumerate(gains):
        ends = (chain[k], chain[k + 1]) if letter in "eh" else (plus, minus)
        ctrl = tuple(controls_list[2 * k : 2 * k + 2]) if inputs == "vd" else (controls_list[k],)
        out.append(RefElement(f"{name}.t{k}", letter, ends, gain, ctrl))
    return out


def parse_reading(listing: list[str]) -> Reading:
    """Elements of ngspice's expanded listing (title line and dot cards skipped)."""
    elements: list[RefElement] = []
    nonlinear: list[str] = []
    models: dict[str, list[float]] = {}
    for text in listing:
        found = _POLY_MODEL.match(text.lower().strip())
        if found:
            models[found.group(1)] = [spice_value(c) for c in found.group(2).split()]
    for text in listing:
        low = text.lower()
        if not low or low.startswith(("*", ".")):
            continue
        fields = low.split()
        name, letter = fields[0], low[0]
        if re.fullmatch(r"bpa_\d+", name):
            continue  # ngspice's own B source for a par('...') in .measure/.print: drives nothing
        poly = _linear_poly(low.strip(), models)
        if poly is not None:
            elements.extend(poly)
            continue
        if letter not in LINEAR_LETTERS:
            nonlinear.append(name)
            continue
        if any(w in low for w in ("{", "value=", "vol=", "cur=", "poly", "table", "laplace", "freq=")):
            raise ReferenceUnavailable(f"{name}: behavioural form in ngspice's listing: {text}")
        if letter in "rcl":
            positional, kw = _keyword_values(fields[3:])
            key = {"r": "r", "c": "c", "l": "l"}[letter]
            raw = kw.get(key) or kw.get({"r": "resistance", "c": "capacitance", "l": "inductance"}[letter])
            if raw is None:
                numbers = [p for p in positional if _NUMBER.match(p)]
                # ``R1 a b rmod 1k``: a model name beside the value (the op/ac check
                # below catches a model whose parameters change the value).
                if len(numbers) != 1 or len(positional) > 2:
                    raise ReferenceUnavailable(f"{name}: no single value in ngspice's listing: {text}")
                raw = numbers[0]
            if letter == "r" and "ac" in kw:
                raise ReferenceUnavailable(f"{name}: separate AC resistance: {text}")
            value = spice_value(raw)
            mult = spice_value(kw["m"]) if "m" in kw else 1.0
            value = {"r": value / mult, "c": value * mult, "l": value / mult}[letter]
            elements.append(RefElement(name, letter, tuple(fields[1:3]), value))
        elif letter in "vi":
            series = 0.0
            if "portnum" in low:
                if letter == "i":
                    raise ReferenceUnavailable(f"{name}: S-parameter port on a current source: {text}")
                # ngspice's S-parameter port: a voltage source behind its z0 (default 50 Ω).
                tok = _tokens(low.replace("=", " "))
                series = spice_value(tok[tok.index("z0") + 1]) if "z0" in tok else 50.0
            elements.append(RefElement(name, letter, tuple(fields[1:3]), series))
        elif letter in "eg":
            tok = _tokens(low)
            if len(tok) < 6:
                raise ReferenceUnavailable(f"{name}: unexpected form: {text}")
            elements.append(RefElement(name, letter, tuple(tok[1:3]), spice_value(tok[5]), tuple(tok[3:5])))
        elif letter in "fh":
            tok = _tokens(low)
            if len(tok) < 5:
                raise ReferenceUnavailable(f"{name}: unexpected form: {text}")
            elements.append(RefElement(name, letter, tuple(tok[1:3]), spice_value(tok[4]), (tok[3],)))
        elif letter == "k":
            tok = _tokens(low)
            elements.append(RefElement(name, letter, (), spice_value(tok[3]), tuple(tok[1:3])))
    return Reading(elements, listing, nonlinear)


# ---------------------------------------------------------------- the pencil


def _is_probe(name: str) -> bool:
    """ngspice's own 0 V ammeters for ``.probe`` (``vcurr_…``): not inputs of the circuit."""
    return name.startswith("vcurr_")


def top_level_nodes(pencil: Pencil) -> list[str]:
    """Nodes the file itself names (not ``x1.n`` nor ngspice's ``probe_int_…``)."""
    return [n for n in pencil.nodes if "." not in n and not n.startswith("probe_int_")]


def build_pencil(reading: Reading) -> Pencil:
    elements = reading.elements
    nodes: list[str] = []
    for e in elements:
        for n in (*e.nodes, *(e.control if e.letter in "eg" else ())):
            if n != "0" and n not in nodes:
                nodes.append(n)
    branches = [e.name for e in elements if e.letter in "vleh"]
    sources = [e.name for e in elements if e.letter in "vi" and not _is_probe(e.name)]
    size = len(nodes) + len(branches)
    index = {n: i for i, n in enumerate(nodes)}
    bindex = {b: len(nodes) + i for i, b in enumerate(branches)}
    g = np.zeros((size, size))
    c = np.zeros((size, size))
    bu = np.zeros((size, len(sources)))

    def at(node: str) -> int | None:
        return None if node == "0" else index[node]

    def conductance(mat: np.ndarray, a: str, b: str, val: float) -> None:
        for p, sp in ((a, 1.0), (b, -1.0)):
            for q, sq in ((a, 1.0), (b, -1.0)):
                if at(p) is not None and at(q) is not None:
                    mat[at(p), at(q)] += sp * sq * val

    def branch(row: int, a: str, b: str) -> None:
        """Branch current z[row] leaves a and enters b; its row starts with v(a) − v(b)."""
        for n, sgn in ((a, 1.0), (b, -1.0)):
            if at(n) is not None:
                g[at(n), row] += sgn
                g[row, at(n)] += sgn

    inductors = {e.name: e for e in elements if e.letter == "l"}
    for e in elements:
        if e.letter == "r":
            conductance(g, *e.nodes, 1.0 / e.value)
        elif e.letter == "c":
            conductance(c, *e.nodes, e.value)
        elif e.letter == "l":
            branch(bindex[e.name], *e.nodes)
            c[bindex[e.name], bindex[e.name]] -= e.value
        elif e.letter == "v":
            branch(bindex[e.name], *e.nodes)
            g[bindex[e.name], bindex[e.name]] -= e.value  # port resistance (0 for a plain source)
            if e.name in sources:
                bu[bindex[e.name], sources.index(e.name)] = 1.0
        elif e.letter == "i":
            a, b = e.nodes
            if at(a) is not None:
                bu[at(a), sources.index(e.name)] -= 1.0
            if at(b) is not None:
                bu[at(b), sources.index(e.name)] += 1.0
        elif e.letter == "e":
            row = bindex[e.name]
            branch(row, *e.nodes)
            for n, sgn in zip(e.control, (1.0, -1.0), strict=True):
                if at(n) is not None:
                    g[row, at(n)] -= sgn * e.value
        elif e.letter == "g":
            for n, sgn in zip(e.nodes, (1.0, -1.0), strict=True):
                for cn, csg in zip(e.control, (1.0, -1.0), strict=True):
                    if at(n) is not None and at(cn) is not None:
                        g[at(n), at(cn)] += sgn * csg * e.value
        elif e.letter in "fh":
            ctrl = e.control[0]
            if ctrl not in bindex:
                raise ReferenceUnavailable(f"{e.name}: controlling element {ctrl} carries no branch current")
            if e.letter == "f":
                for n, sgn in zip(e.nodes, (1.0, -1.0), strict=True):
                    if at(n) is not None:
                        g[at(n), bindex[ctrl]] += sgn * e.value
            else:
                row = bindex[e.name]
                branch(row, *e.nodes)
                g[row, bindex[ctrl]] -= e.value
        elif e.letter == "k":
            la, lb = (inductors.get(n) for n in e.control)
            if la is None or lb is None:
                raise ReferenceUnavailable(f"{e.name}: couples an unknown inductor")
            mutual = e.value * math.sqrt(la.value * lb.value)
            c[bindex[la.name], bindex[lb.name]] -= mutual
            c[bindex[lb.name], bindex[la.name]] -= mutual
    return Pencil(g, c, bu, nodes, branches, sources)


# ---------------------------------------------------------------- check against ngspice


def _read_raw(path: Path) -> list[tuple[str, dict[str, np.ndarray]]]:
    """Plots of an ASCII rawfile: (plot name, {vector: values})."""
    plots = []
    lines = path.read_text().splitlines()
    i = 0
    while i < len(lines):
        if not lines[i].startswith("Title:"):
            i += 1
            continue
        plotname, nvars, npoints, names = "", 0, 0, []
        while not lines[i].startswith("Variables:"):
            key, _, val = lines[i].partition(":")
            if key == "Plotname":
                plotname = val.strip()
            elif key == "No. Variables":
                nvars = int(val)
            elif key == "No. Points":
                npoints = int(val)
            i += 1
        i += 1
        for _ in range(nvars):
            names.append(lines[i].split()[1].lower())
            i += 1
        i += 1  # "Values:"
        data = np.zeros((npoints, nvars), dtype=complex)
        for p in range(npoints):
            for v in range(nvars):
                while not lines[i].strip():
                    i += 1
                field_ = lines[i].split()[-1]
                re_, _, im_ = field_.partition(",")
                data[p, v] = complex(float(re_), float(im_ or 0.0))
                i += 1
        plots.append((plotname, {n: data[:, k] for k, n in enumerate(names)}))
    return plots


def _pencil_vector(pencil: Pencil, name: str, z: np.ndarray) -> complex | None:
    if name.startswith("v(") and name.endswith(")"):
        node = name[2:-1]
        return z[pencil.nodes.index(node)] if node in pencil.nodes else None
    if name.startswith("i(") and name.endswith(")"):
        br = name[2:-1]
        return z[len(pencil.nodes) + pencil.branches.index(br)] if br in pencil.branches else None
    return None


def _check_plot(pencil: Pencil, vectors: dict[str, np.ndarray], point: int, z: np.ndarray, what: str) -> int:
    """Compare one solution point; returns how many vectors were compared."""
    groups: dict[str, list[tuple[complex, complex, str]]] = {"v": [], "i": []}
    nn = len(pencil.nodes)
    gmax = float(np.abs(pencil.G[:nn, :nn]).max(initial=0.0))
    for name, values in vectors.items():
        mine = _pencil_vector(pencil, name, z)
        if mine is None:
            continue
        groups[name[0]].append((complex(mine), complex(values[point]), name))
    vmax = max((abs(b) for _, b, _ in groups["v"]), default=0.0)
    for kind, pairs in groups.items():
        if not pairs:
            continue
        # A current is measured against the largest voltage times the largest
        # conductance, so an exact zero current is not compared with rounding.
        scale = max(abs(b) for _, b, _ in pairs)
        if kind == "i":
            scale = max(scale, vmax * gmax)
        for a, b, name in pairs:
            if abs(a - b) > NGSPICE_RTOL * max(scale, 1e-300):
                raise ReferenceUnavailable(
                    f"listing reader disagrees with ngspice's own {what} on {name}: {a:.9g} vs {b:.9g}"
                )
    return sum(len(p) for p in groups.values())


def check_against_ngspice(deck: Path, pencil: Pencil, workdir: Path) -> dict[str, int]:
    """Run ngspice's op and ac with known source values; the pencil must reproduce them."""
    m = len(pencil.sources)
    dc = np.array([1.0 + 0.37 * k for k in range(m)])
    ac = np.array([0.5 + 0.29 * k for k in range(m)])
    cmds = []
    for name, d, a in zip(pencil.sources, dc, ac, strict=True):
        cmds += [f"alter @{name}[dc]={d:.17g}", f"alter @{name}[acmag]={a:.17g}"]
    op_raw, ac_raw = workdir / "op.raw", workdir / "ac.raw"
    cmds += ["set filetype=ascii", "op", f"write {op_raw}"]
    fl = " ".join(f"{f:.6g}" for f in (AC_FREQUENCIES[0], AC_FREQUENCIES[-1]))
    cmds += [f"ac dec 1 {fl}", f"write {ac_raw}"]
    out = _run(deck, cmds, workdir)
    counts = {"op": 0, "ac": 0}
    if op_raw.exists():
        plots = _read_raw(op_raw)
        if plots:
            try:
                z = pencil.solve(0.0, dc)
            except np.linalg.LinAlgError:
                z = None
            if z is not None:
                counts["op"] = _check_plot(pencil, plots[0][1], 0, z, "operating point")
    if not ac_raw.exists():
        first = next((ln for ln in out.splitlines() if "rror" in ln), "no ac output")
        raise ReferenceUnavailable(f"ngspice ac failed: {first.strip()}")
    _, vectors = _read_raw(ac_raw)[0]
    freqs = vectors.pop("frequency").real
    for p, f in enumerate(freqs):
        z = pencil.solve(2j * math.pi * f, ac)
        counts["ac"] += _check_plot(pencil, vectors, p, z, f"ac at {f:.4g} Hz")
    if counts["ac"] == 0:
        raise ReferenceUnavailable("ngspice's ac printed no vector the pencil knows")
    return counts


# ---------------------------------------------------------------- the pencil's spectrum


def finite_eigenvalues(pencil: Pencil) -> np.ndarray:
    """Finite λ with det(G + λC) = 0, by shift-invert: μ = 1/(σ − λ) of (G + σC)⁻¹C."""
    n = pencil.G.shape[0]
    if n == 0 or not pencil.C.any():
        return np.zeros(0, dtype=complex)
    rng = np.random.default_rng(12345)
    sigma = complex(-0.3, 0.7)
    lam = np.zeros(0, dtype=complex)
    for _ in range(2):
        mat = pencil.G + sigma * pencil.C
        if np.linalg.cond(mat) > 1e14:
            sigma *= complex(1.3, 0.2) + 0.1 * rng.standard_normal()
            continue
        mu = np.linalg.eigvals(np.linalg.solve(mat, pencil.C))
        big = np.abs(mu).max()
        # Infinite eigenvalues give μ = 0 up to rounding (μ ≈ √eps·max|μ| for
        # an index-2 Jordan block); finite ones |μ| ≥ 1/(|σ| + |λ|).
        keep = np.abs(mu) > 1e-7 * big
        lam = sigma - 1.0 / mu[keep]
        nonzero = np.abs(lam[np.abs(lam) > 1e-12 * np.abs(lam).max(initial=0.0)])
        scale = float(np.exp(np.mean(np.log(nonzero)))) if nonzero.size else 1.0
        sigma = scale * complex(-0.31, 0.73)
    if np.linalg.cond(pencil.G + sigma * pencil.C) > 1e14:
        raise ReferenceUnavailable("singular MNA pencil (a node or loop is left undetermined)")
    return _refine_far_eigenvalues(pencil, lam, sigma)


def _refine_far_eigenvalues(pencil: Pencil, lam: np.ndarray, sigma: complex) -> np.ndarray:
    """Recompute eigenvalues far from the shift with a shift next to each of them.

    λ = σ − 1/μ loses relative accuracy as |λ| grows past |σ| (μ is then small against the
    largest μ), e.g. a −6.7e8 pole beside −7e3 ones came out 1.4e-5 off with a spurious
    imaginary part. A second shift-invert at σ' ≈ λ makes that μ the largest one.
    """
    far = np.flatnonzero(np.abs(lam) > 1e3 * abs(sigma))
    if not far.size or far.size > 20 or pencil.G.shape[0] > 400:
        return lam
    out = lam.copy()
    for k in far:
        shift = lam[k] * complex(1.0, 1e-3)
        mat = pencil.G + shift * pencil.C
        if np.linalg.cond(mat) > 1e14:
            continue
        mu = np.linalg.eigvals(np.linalg.solve(mat, pencil.C))
        candidates = shift - 1.0 / mu[np.abs(mu) > 0]
        out[k] = candidates[np.argmin(np.abs(candidates - lam[k]))]
    return out


def match_spectra(ours: np.ndarray, ref: np.ndarray) -> float:
    """Worst relative distance of an optimal one-to-one matching (inf if counts differ)."""
    if len(ours) != len(ref):
        return math.inf
    if not len(ref):
        return 0.0
    rho = float(np.abs(ref).max())
    cost = np.abs(np.asarray(ours)[:, None] - np.asarray(ref)[None, :])
    rows, cols = scipy.optimize.linear_sum_assignment(cost)
    scale = np.maximum(np.abs(ref[cols]), ZERO_FLOOR * rho)
    return float((cost[rows, cols] / scale).max())


def probe_frequencies(eigs: np.ndarray) -> list[complex]:
    """Three complex frequencies (rad/s) at the circuit's own scale, away from its poles."""
    nonzero = np.abs(eigs[np.abs(eigs) > 1e-12 * np.abs(eigs).max(initial=0.0)])
    scale = float(np.exp(np.mean(np.log(nonzero)))) if nonzero.size else 1.0
    out = []
    for base in (complex(0.37, 1.13), complex(1.71, 0.23), complex(0.05, 2.9)):
        s = base * scale
        while eigs.size and np.abs(eigs - s).min() < 1e-3 * abs(s):
            s *= complex(1.07, 0.05)
        out.append(s)
    return out


# ---------------------------------------------------------------- the verdict


@dataclass
class Outcome:
    """What happened to one file."""

    status: str  # "agree", "refused", "wrong", "no-reference"
    detail: str = ""
    states: int = 0
    checked: dict[str, int] = field(default_factory=dict)


@dataclass
class Reference:
    """Checked reference for one file."""

    pencil: Pencil
    eigenvalues: np.ndarray
    checked: dict[str, int]


def build_reference(path: Path, drop: tuple[str, ...] = ()) -> tuple[Reading, Reference | None]:
    """ngspice's reading of ``path``; the checked pencil unless the listing is nonlinear."""
    with tempfile.TemporaryDirectory(prefix="ndref") as tmp:
        workdir = Path(tmp)
        deck = _deck(Path(path).resolve(), workdir, tuple(d.lower() for d in drop))
        out = _run(deck, ["listing e"], workdir)
        fatal = [ln for ln in out.splitlines() if ln.lower().startswith(("error", "fatal"))]
        fatal = [ln for ln in fatal if "no graphics interface" not in ln]
        reading = parse_reading(read_listing(out))
        if fatal:
            raise ReferenceUnavailable(f"ngspice reports: {fatal[0].strip()}")
        if reading.nonlinear:
            return reading, None
        pencil = build_pencil(reading)
        if pencil.G.shape[0] > MAX_UNKNOWNS:
            raise ReferenceUnavailable(
                f"{pencil.G.shape[0]} MNA unknowns: above the reference's {MAX_UNKNOWNS}"
            )
        if not pencil.sources:
            raise ReferenceUnavailable("no independent source: nothing for ngspice's ac to check")
        checked = check_against_ngspice(deck, pencil, workdir)
    return reading, Reference(pencil, finite_eigenvalues(pencil), checked)


def _source_key(ngspice_name: str) -> str:
    """``v.x1.vs`` → ``x1.vs``; ``v1`` → ``v1`` (netlistdyn's hierarchical spelling, case-folded)."""
    if "." in ngspice_name:
        return ngspice_name.split(".", 1)[1]
    return ngspice_name


def compare_model(path: Path, ref: Reference) -> Outcome:
    """netlistdyn's model of ``path`` against the checked pencil."""
    import netlistdyn
    from netlistdyn.analysis.eigen import analyze_eigenvalues

    pencil = ref.pencil
    top_nodes = top_level_nodes(pencil)
    outputs = [f"v({n})" for n in top_nodes]
    model = netlistdyn.compile(path, outputs=outputs or None)
    ours = np.array([m.value for m in analyze_eigenvalues(model.A_sparse).modes], dtype=complex)
    worst = match_spectra(ours, ref.eigenvalues)
    if worst > MODEL_RTOL:
        return Outcome(
            "wrong",
            f"eigenvalues: netlistdyn {len(ours)}, ngspice's reading {len(ref.eigenvalues)}; "
            f"worst relative distance {worst:.3g}",
            model.nstates,
        )
    keys = [_source_key(s) for s in pencil.sources]
    inputs = [name.lower() for name in model.inputs]
    if sorted(inputs) != sorted(keys):
        return Outcome("wrong", f"inputs differ: netlistdyn {inputs}, ngspice {keys}", model.nstates)
    order = [inputs.index(k) for k in keys]
    rows = pencil.node_rows(top_nodes)
    worst_tf = 0.0
    for s in probe_frequencies(ref.eigenvalues):
        mine = model.transfer_function(s)[:, order] if outputs else np.zeros((0, len(keys)))
        theirs = rows @ np.linalg.solve(pencil.G + s * pencil.C, pencil.Bu)
        if theirs.size:
            col = np.abs(theirs).max(axis=0, keepdims=True)
            scale = np.maximum(np.abs(theirs), np.maximum(col, 1e-300) * 1e-6)
            worst_tf = max(worst_tf, float((np.abs(mine - theirs) / scale).max()))
    if worst_tf > MODEL_RTOL:
        return Outcome("wrong", f"transfer matrix: worst relative error {worst_tf:.3g}", model.nstates)
    return Outcome("agree", f"eig {worst:.1g}, tf {worst_tf:.1g}", model.nstates, ref.checked)


def classify(path: Path, drop: tuple[str, ...] = ()) -> Outcome:
    """Build the reference from ngspice's reading and judge netlistdyn on ``path``."""
    from netlistdyn.base.errors import NetlistError

    try:
        reading, ref = build_reference(path, drop)
    except ReferenceUnavailable as exc:
        return Outcome("no-reference", str(exc))
    except subprocess.TimeoutExpired:
        return Outcome("no-reference", "ngspice timed out")
    try:
        if ref is None:
            import netlistdyn

            model = netlistdyn.compile(path)
            return Outcome(
                "wrong",
                f"compiled ({model.nstates} states) though ngspice reads nonlinear devices: "
                + ", ".join(reading.nonlinear[:5]),
            )
        return compare_model(path, ref)
    except NetlistError as exc:
        message = str(exc)
        if "\n" in message.strip():
            return Outcome("wrong", f"refusal is not one line: {message!r}")
        return Outcome("refused", message.strip())


def classify_text(text: str | bytes, directory: Path, name: str = "probe.cir") -> Outcome:
    """:func:`classify` of a netlist given as text (written to ``directory/name``).

    For one-construct probes in tests: ``classify_text(netlist, tmp_path).status``
    is ``agree`` only when netlistdyn reads the construct as ngspice does.
    """
    path = Path(directory) / name
    path.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return classify(path)
