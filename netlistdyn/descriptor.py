"""Netlist → sparse descriptor system ``E x' = A x + B u``, ``y = C x + D u``.

Modified nodal analysis, assembled directly in sparse form: the unknowns are
the node voltages ``v(n)`` (V), the inductor currents ``i(L)`` (A) and the
currents of voltage sources and of E/H controlled sources ``i(V)`` (A), all
in netlist order. ``E`` holds the capacitances and inductances, so nodes
without a capacitor and source currents are algebraic unknowns (rows of ``E``
that are zero); nothing is eliminated, and the matrices keep the sparsity of
the circuit. Assembly is linear in the number of elements.

The explicit state-space model of :mod:`netlistdyn.formulate` has the states
``q(C)`` of tree capacitors and ``i(L)`` of link inductors; the same states
are linear functions of the descriptor unknowns (``q(C) = C·(v(a) − v(b))``).
For large circuits the dense elimination that produces ``A`` is what costs
memory, which this form avoids.

Signs follow SPICE: ``i(X)`` flows from X's n+ through X to its n−, and a
current source ``I n+ n− u`` takes ``u`` out of n+ and puts it into n−.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .errors import NetlistError, UsageError
from .netlist import GROUND, Kind, Netlist
from .probes import Probe, default_probes, parse_probe

#: Element kinds the descriptor form assembles.
SUPPORTED = frozenset(
    {
        Kind.RESISTOR,
        Kind.CAPACITOR,
        Kind.INDUCTOR,
        Kind.VSOURCE,
        Kind.ISOURCE,
        Kind.VCCS,
        Kind.VCVS,
        Kind.CCCS,
        Kind.CCVS,
        Kind.COUPLING,
    }
)


@dataclass(frozen=True)
class DescriptorSystem:
    """A linear circuit as ``E x' = A x + B u``, ``y = C x + D u`` (sparse).

    Attributes
    ----------
    E, A : scipy.sparse.csc_array
        ``(n, n)``: capacitances (F) / inductances (H), and conductances,
        incidences and controlled-source gains.
    B : scipy.sparse.csc_array
        ``(n, m)``: where each independent source enters.
    C, D : scipy.sparse.csr_array
        ``(p, n)`` and ``(p, m)``: the requested outputs.
    variables : tuple of str
        Names of the unknowns: ``v(node)``, ``i(L)``, ``i(V)``.
    inputs : tuple of str
        Independent sources (element names), in netlist order.
    outputs : tuple of str
        Output labels (``v(n)``, ``i(R1)``...).
    nnodes : int
        Number of non-ground nodes (the first ``nnodes`` unknowns).
    dynamic : int
        Number of non-zero rows of ``E`` (capacitor nodes and inductors).
    title : str
        The netlist's title.
    """

    E: sp.csc_array
    A: sp.csc_array
    B: sp.csc_array
    C: sp.csr_array
    D: sp.csr_array
    variables: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    nnodes: int
    dynamic: int
    title: str = ""

    @property
    def size(self) -> int:
        """Number of unknowns."""
        return int(self.A.shape[0])


def supports(netlist: Netlist) -> bool:
    """True when every element of the netlist can be assembled here."""
    return all(e.kind in SUPPORTED and e.keyword is None for e in netlist.elements)


class _Triplets:
    """Growing COO lists for one sparse matrix."""

    def __init__(self) -> None:
        self.rows: list[int] = []
        self.cols: list[int] = []
        self.vals: list[float] = []

    def add(self, row: int, col: int, value: float) -> None:
        if row >= 0 and col >= 0:
            self.rows.append(row)
            self.cols.append(col)
            self.vals.append(value)

    def branch(self, a: int, b: int, col_a: int, col_b: int, value: float) -> None:
        """The 2x2 stamp ``value·[[1, −1], [−1, 1]]`` on rows (a, b), columns (col_a, col_b)."""
        self.add(a, col_a, value)
        self.add(a, col_b, -value)
        self.add(b, col_a, -value)
        self.add(b, col_b, value)

    def matrix(self, shape: tuple[int, int]) -> sp.csc_array:
        return sp.csc_array(
            (np.asarray(self.vals, dtype=float), (np.asarray(self.rows), np.asarray(self.cols))), shape=shape
        )


def assemble(netlist: Netlist, outputs: Sequence[str] | None = None) -> DescriptorSystem:
    """Assemble the MNA descriptor system of a linear netlist.

    Parameters
    ----------
    netlist : Netlist
        R, L, C, V, I, K and E, G, F, H elements only (see :func:`supports`).
    outputs : sequence of str, optional
        ``v(n)``, ``v(a,b)``, ``i(X)`` (X not a capacitor); default every
        node voltage.

    Returns
    -------
    DescriptorSystem

    Raises
    ------
    NetlistError
        An element the descriptor form does not handle, or an unknown
        controlling source.
    UsageError
        An output the descriptor form cannot give.
    """
    nodes = netlist.nodes
    index = {node: k for k, node in enumerate(nodes)}
    index[GROUND] = -1
    n_nodes = len(nodes)
    names = [f"v({node})" for node in nodes]
    branch_of: dict[str, int] = {}  # element key -> index of its current unknown
    inductance: dict[str, float] = {}
    for elem in netlist.elements:
        if elem.kind not in SUPPORTED or elem.keyword is not None:
            raise NetlistError(f"{elem.label}: not supported by the sparse descriptor form", elem.loc)
        if elem.kind in (Kind.INDUCTOR, Kind.VSOURCE, Kind.VCVS, Kind.CCVS):
            branch_of[elem.key] = n_nodes + len(branch_of)
            names.append(f"i({elem.name})")
            if elem.kind is Kind.INDUCTOR:
                inductance[elem.key] = elem.value
    n = n_nodes + len(branch_of)
    sources = netlist.sources
    source_col = {e.key: j for j, e in enumerate(sources)}
    e_t, a_t, b_t = _Triplets(), _Triplets(), _Triplets()
    for elem in netlist.elements:
        a, b = (index[elem.nodes[0]], index[elem.nodes[1]]) if len(elem.nodes) == 2 else (-1, -1)
        kind = elem.kind
        if kind is Kind.RESISTOR:
            a_t.branch(a, b, a, b, -1.0 / elem.value)
        elif kind is Kind.CAPACITOR:
            e_t.branch(a, b, a, b, elem.value)
        elif kind is Kind.ISOURCE:
            b_t.add(a, source_col[elem.key], -1.0)
            b_t.add(b, source_col[elem.key], 1.0)
        elif kind is Kind.VCCS:
            c, d = (index[node] for node in elem.control_nodes or (GROUND, GROUND))
            a_t.branch(a, b, c, d, -elem.value)
        elif kind is Kind.COUPLING:
            first, second = elem.coupled or ("", "")
            if first not in inductance or second not in inductance:
                raise NetlistError(f"{elem.name}: couples an element that is not an inductor", elem.loc)
            mutual = elem.value * float(np.sqrt(inductance[first] * inductance[second]))
            e_t.add(branch_of[first], branch_of[second], mutual)
            e_t.add(branch_of[second], branch_of[first], mutual)
        elif kind is Kind.CCCS:
            sense = branch_of.get(elem.control_source or "")
            if sense is None:
                raise NetlistError(f"{elem.name}: no voltage source {elem.control_source!r}", elem.loc)
            a_t.add(a, sense, -elem.value)
            a_t.add(b, sense, elem.value)
        else:  # the current unknown k of L, V, E, H: KCL columns and its own branch row
            k = branch_of[elem.key]
            a_t.add(a, k, -1.0)
            a_t.add(b, k, 1.0)
            a_t.add(k, a, 1.0)
            a_t.add(k, b, -1.0)
            if kind is Kind.INDUCTOR:
                e_t.add(k, k, elem.value)
            elif kind is Kind.VSOURCE:
                b_t.add(k, source_col[elem.key], -1.0)
            elif kind is Kind.VCVS:
                c, d = (index[node] for node in elem.control_nodes or (GROUND, GROUND))
                a_t.add(k, c, -elem.value)
                a_t.add(k, d, elem.value)
            else:  # CCVS
                sense = branch_of.get(elem.control_source or "")
                if sense is None:
                    raise NetlistError(f"{elem.name}: no voltage source {elem.control_source!r}", elem.loc)
                a_t.add(k, sense, -elem.value)
    E = e_t.matrix((n, n))
    A = a_t.matrix((n, n))
    B = b_t.matrix((n, len(sources)))
    E.eliminate_zeros()
    probes = [parse_probe(text, netlist) for text in outputs] if outputs else default_probes(netlist)
    C, D = _output_rows(probes, netlist, index, branch_of, source_col, n)
    dynamic = int(np.count_nonzero(np.diff(E.tocsr().indptr)))
    return DescriptorSystem(
        E,
        A,
        B,
        C,
        D,
        tuple(names),
        tuple(e.name for e in sources),
        tuple(p.name for p in probes),
        n_nodes,
        dynamic,
        netlist.title,
    )


def _output_rows(
    probes: Sequence[Probe],
    netlist: Netlist,
    index: dict[str, int],
    branch_of: dict[str, int],
    source_col: dict[str, int],
    n: int,
) -> tuple[sp.csr_array, sp.csr_array]:
    c_t, d_t = _Triplets(), _Triplets()
    for row, probe in enumerate(probes):
        if probe.kind == "v":
            c_t.add(row, index[probe.nodes[0]], 1.0)
            c_t.add(row, index[probe.nodes[1]], -1.0)
            continue
        if probe.kind != "i":
            raise UsageError(f"--output {probe.name}: not available in the sparse descriptor form")
        elem = netlist.element(probe.element)
        a, b = index[elem.nodes[0]], index[elem.nodes[1]]
        if elem.key in branch_of:
            c_t.add(row, branch_of[elem.key], 1.0)
        elif elem.kind is Kind.RESISTOR:
            c_t.add(row, a, 1.0 / elem.value)
            c_t.add(row, b, -1.0 / elem.value)
        elif elem.kind is Kind.ISOURCE:
            d_t.add(row, source_col[elem.key], 1.0)
        elif elem.kind is Kind.VCCS:
            c, d = (index[node] for node in elem.control_nodes or (GROUND, GROUND))
            c_t.add(row, c, elem.value)
            c_t.add(row, d, -elem.value)
        elif elem.kind is Kind.CCCS:
            c_t.add(row, branch_of[elem.control_source or ""], elem.value)
        else:
            raise UsageError(
                f"--output {probe.name}: a capacitor current is not available in the sparse descriptor form"
            )
    p = len(probes)
    return c_t.matrix((p, n)).tocsr(), d_t.matrix((p, len(source_col))).tocsr()


def initial_inputs(netlist: Netlist) -> NDArray[np.float64]:
    """Each source's value at t = 0 (its transient waveform's, else its DC value)."""
    out = np.empty(len(netlist.sources))
    for j, elem in enumerate(netlist.sources):
        out[j] = elem.value if elem.waveform is None else float(np.asarray(elem.waveform(0.0)))
    return out
