"""Ask ngspice 39 (batch, ``ngspice -b``) how it reads a netlist, and compare with ours.

ngspice's reading of a text is observed through its DC operating point
(``op``; ``print all``) and its small-signal response (``ac``), printed with
15 digits. Our reading of the same text is evaluated with the independent
MNA reference of :mod:`tests.mna` (which shares nothing with the compiler but
the parser), so a test that agrees shows that both programs read the same
circuit. Tests skip cleanly when ngspice is not installed.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

from netlistdyn.circuit.netlist import Netlist
from tests.mna import build_mna

NGSPICE = shutil.which("ngspice")
needs_ngspice = pytest.mark.skipif(NGSPICE is None, reason="ngspice is not installed")
_VALUE = re.compile(r"^\s*(\S+)\s*=\s*([-+0-9.eE]+|inf|nan)\s*$", re.IGNORECASE)


class NgspiceRefused(RuntimeError):
    """ngspice did not read the netlist (its error text is the message)."""


def run_ngspice(
    text: str, control: str, directory: Path | None = None, encoding: str = "utf-8"
) -> dict[str, float]:
    """Run ``ngspice -b`` on ``text`` with a ``.control`` block; return printed scalars.

    ``text`` is written as given (its ``.end`` line, if any, is moved after
    the control block).
    """
    assert NGSPICE is not None
    body = re.sub(r"(?im)^\.end\s*$", "", text)
    # A separate 0 V source keeps "print all" from naming a lone vector "all".
    deck = f"{body.rstrip()}\nvprobe_dummy probe_dummy 0 0\n.control\nset numdgt=15\n{control}\n.endc\n.end\n"
    with tempfile.TemporaryDirectory(dir=directory) as tmp:
        path = Path(tmp) / "probe.cir"
        path.write_bytes(deck.encode(encoding))
        result = subprocess.run(
            [NGSPICE, "-b", str(path)], capture_output=True, text=True, timeout=60, cwd=tmp, errors="replace"
        )
    out = result.stdout + result.stderr
    if "error" in out.lower() and not any(_VALUE.match(line) for line in out.splitlines()):
        raise NgspiceRefused(out)
    values: dict[str, float] = {}
    for line in out.splitlines():
        match = _VALUE.match(line)
        if match:
            values[match.group(1).lower()] = float(match.group(2))
    if not values:
        raise NgspiceRefused(out)
    return values


def ngspice_tran(text: str, vectors: list[str]) -> np.ndarray:
    """ngspice's ``.tran`` (the text's own ``.tran`` line): columns time, then each vector."""
    assert NGSPICE is not None
    body = re.sub(r"(?im)^\.end\s*$", "", text)
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "out.txt"
        deck = f"{body.rstrip()}\n.control\nrun\nwrdata {data} {' '.join(vectors)}\n.endc\n.end\n"
        (Path(tmp) / "probe.cir").write_text(deck)
        result = subprocess.run(
            [NGSPICE, "-b", "probe.cir"], capture_output=True, text=True, timeout=60, cwd=tmp
        )
        if not data.exists():
            raise NgspiceRefused(result.stdout + result.stderr)
        table = np.loadtxt(data, ndmin=2)
    # wrdata writes (time, value) pairs per vector
    return np.column_stack([table[:, 0], *(table[:, 2 * k + 1] for k in range(len(vectors)))])


def ngspice_op(text: str, **kwargs) -> dict[str, float]:
    """ngspice's DC operating point: node voltages (V) and ``vname#branch`` currents (A)."""
    return run_ngspice(text, "op\nprint all", **kwargs)


def ngspice_ac(text: str, node: str, freq: float) -> complex:
    """``v(node)`` of ngspice's ``.ac`` at ``freq`` (Hz) (the text's ``AC`` sources drive it)."""
    got = run_ngspice(text, f"ac lin 1 {freq!r} {freq!r}\nprint real(v({node}))\nprint imag(v({node}))")
    return complex(got[f"real(v({node}))"], got[f"imag(v({node}))"])


def our_op(netlist: Netlist) -> dict[str, float]:
    """Our reading's DC node voltages (MNA at s = 0, sources at their DC values)."""
    mna = build_mna(netlist)
    u = np.array([e.value for e in netlist.sources], dtype=float)
    z = np.linalg.solve(mna.G, mna.Bu @ u)
    return {node: float(z[i]) for node, i in mna.node_index.items()}


def our_ac(netlist: Netlist, node: str, freq: float, source: str) -> complex:
    """Our reading's ``v(node)`` per unit of ``source`` at ``freq`` (Hz)."""
    mna = build_mna(netlist)
    column = [e.key for e in netlist.sources].index(source.lower())
    return complex(mna.transfer([f"v({node})"], 2j * math.pi * freq)[0, column])


def assert_same_op(netlist: Netlist, text: str, rtol: float = 1e-9, **kwargs) -> dict[str, float]:
    """Every node voltage of our reading equals ngspice's ``op`` of the same text.

    rtol 1e-9: both are direct linear solves of the same small circuit;
    ngspice prints 15 digits (``numdgt``); its gmin (1e-12 S) shunts are
    below that on these circuits' kΩ-level impedances.
    """
    theirs = ngspice_op(text, **kwargs)
    ours = our_op(netlist)
    compared = 0
    for node, value in ours.items():
        key = node if node in theirs else f"v({node})"  # ngspice prints numeric nodes as v(1)
        if key in theirs:
            compared += 1
            assert value == pytest.approx(theirs[key], rel=rtol, abs=1e-12), (node, value, theirs[key])
    assert compared, f"no common node: ours {sorted(ours)}, ngspice {sorted(theirs)}"
    return theirs
