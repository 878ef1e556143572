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

from netlistdyn.base.errors import NetlistError, UsageError
from netlistdyn.circuit.netlist import GROUND, Kind, Netlist
from netlistdyn.circuit.probes import Probe, default_probes, parse_probes
from netlistdyn.circuit.waveforms import Dc
from netlistdyn.devices.registry import REGISTRY
from netlistdyn.devices.traits import Mna, Triplets


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
    """True when every element of the netlist can be assembled here (its device has a stamp)."""
    return all(REGISTRY[e.kind].stamp is not None and e.keyword is None for e in netlist.elements)


def _matrix(triplets: Triplets, shape: tuple[int, int]) -> sp.csc_array:
    return sp.csc_array(
        (np.asarray(triplets.vals, dtype=float), (np.asarray(triplets.rows), np.asarray(triplets.cols))),
        shape=shape,
    )


def assemble(netlist: Netlist, outputs: Sequence[str] | None = None, reduce: bool = True) -> DescriptorSystem:
    """Assemble the MNA descriptor system of a linear netlist.

    Parameters
    ----------
    netlist : Netlist
        R, L, C, V, I, K and E, G, F, H elements only (see :func:`supports`).
    outputs : sequence of str, optional
        ``v(n)``, ``v(a,b)``, ``i(X)`` (X not a capacitor); default every
        node voltage.
    reduce : bool
        Merge the nodes joined by 0 V sources and give the node of a
        grounded supply its source's value (see :func:`reduce_sources`):
        fewer unknowns and no zero diagonal from those sources.

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
        device = REGISTRY[elem.kind]
        if device.stamp is None or elem.keyword is not None:
            raise NetlistError(f"{elem.label}: not supported by the sparse descriptor form", elem.loc)
        if device.branch_current:
            branch_of[elem.key] = n_nodes + len(branch_of)
            names.append(f"i({elem.name})")
            if elem.kind is Kind.INDUCTOR:
                inductance[elem.key] = elem.value
    n = n_nodes + len(branch_of)
    sources = netlist.sources
    source_col = {e.key: j for j, e in enumerate(sources)}
    mna = Mna(index, branch_of, inductance, source_col, Triplets(), Triplets(), Triplets())
    for elem in netlist.elements:
        stamp = REGISTRY[elem.kind].stamp
        assert stamp is not None
        stamp(elem, mna)
    E = _matrix(mna.E, (n, n))
    A = _matrix(mna.A, (n, n))
    B = _matrix(mna.B, (n, len(sources)))
    E.eliminate_zeros()
    probes = parse_probes(outputs, netlist) if outputs else default_probes(netlist)
    C, D = _output_rows(probes, netlist, mna, n)
    if reduce:
        needed = {p.element for p in probes if p.kind == "i"}
        needed |= {e.control_source for e in netlist.elements if e.control_source}
        E, A, B, C, D, names, n_nodes = reduce_sources(
            netlist, E, A, B, C, D, names, n_nodes, branch_of, source_col, needed
        )
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
    probes: Sequence[Probe], netlist: Netlist, mna: Mna, n: int
) -> tuple[sp.csr_array, sp.csr_array]:
    """C and D of the outputs: node voltages, and currents (an unknown's, or the device's own form)."""
    c_t, d_t = Triplets(), Triplets()
    index, branch_of = mna.index, mna.branch_of
    for row, probe in enumerate(probes):
        if probe.kind == "v":
            c_t.add(row, index[probe.nodes[0]], 1.0)
            c_t.add(row, index[probe.nodes[1]], -1.0)
            continue
        if probe.kind != "i":
            raise UsageError(f"--output {probe.name}: not available in the sparse descriptor form")
        elem = netlist.element(probe.element)
        current = REGISTRY[elem.kind].current
        if elem.key in branch_of:
            c_t.add(row, branch_of[elem.key], 1.0)
        elif current is not None:
            current(elem, mna, row, c_t, d_t)
        else:
            raise UsageError(
                f"--output {probe.name}: a capacitor current is not available in the sparse descriptor form"
            )
    p = len(probes)
    return _matrix(c_t, (p, n)).tocsr(), _matrix(d_t, (p, len(mna.source_col))).tocsr()


def reduce_sources(
    netlist: Netlist,
    E: sp.csc_array,
    A: sp.csc_array,
    B: sp.csc_array,
    C: sp.csr_array,
    D: sp.csr_array,
    names: list[str],
    n_nodes: int,
    branch_of: dict[str, int],
    source_col: dict[str, int],
    needed: set[str],
) -> tuple[sp.csc_array, sp.csc_array, sp.csc_array, sp.csr_array, sp.csr_array, list[str], int]:
    """Eliminate 0 V sources (node merges) and grounded supplies (known node voltages).

    A source whose current is asked for or controls an F/H source is kept,
    as is a supply whose node has a capacitor (its derivative would enter).
    With ``x_full = T x + S u`` and P summing the KCL rows of merged nodes
    (where the source currents cancel) and dropping the rows of fixed nodes
    and removed sources: ``E ← P E T``, ``A ← P A T``, ``B ← P (B + A S)``,
    ``C ← C T``, ``D ← D + C S``. The removed currents' columns are checked to
    vanish from ``P A``.
    """
    nodes = netlist.nodes
    index = {node: k for k, node in enumerate(nodes)}
    parent = list(range(n_nodes + 1))  # the last entry stands for ground
    ground = n_nodes

    def find(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    def node_id(name: str) -> int:
        return ground if name == GROUND else index[name]

    removed: list[int] = []
    for elem in netlist.elements:
        if elem.kind is not Kind.VSOURCE or elem.key in needed or elem.value != 0:
            continue
        if elem.waveform is not None and not (isinstance(elem.waveform, Dc) and elem.waveform.value == 0):
            continue
        a, b = find(node_id(elem.nodes[0])), find(node_id(elem.nodes[1]))
        if a == b:
            continue  # a loop of shorts: left to MNA (singular, reported at the DC solve)
        if a == ground:
            a, b = b, a
        parent[a] = b  # ground stays a root
        removed.append(branch_of[elem.key])
    shorted = set(removed)
    has_cap = np.zeros(n_nodes + 1, dtype=bool)
    for elem in netlist.elements:
        if elem.kind is Kind.CAPACITOR:
            for name in elem.nodes:
                has_cap[find(node_id(name))] = True
    fixed: dict[int, tuple[int, float]] = {}
    for elem in netlist.elements:
        if elem.kind is not Kind.VSOURCE or elem.key in needed or branch_of[elem.key] in shorted:
            continue
        a, b = find(node_id(elem.nodes[0])), find(node_id(elem.nodes[1]))
        if b == ground and a != ground and a not in fixed and not has_cap[a]:
            fixed[a] = (source_col[elem.key], 1.0)
        elif a == ground and b != ground and b not in fixed and not has_cap[b]:
            fixed[b] = (source_col[elem.key], -1.0)
        else:
            continue
        removed.append(branch_of[elem.key])
    if not removed:
        return E, A, B, C, D, names, n_nodes
    n_full = A.shape[0]
    reduced: dict[int, int] = {}
    new_names: list[str] = []
    t_rows, t_cols, s_rows, s_cols, s_vals = [], [], [], [], []
    for k in range(n_nodes):
        root = find(k)
        if root == ground:
            continue
        if root in fixed:
            j, sign = fixed[root]
            s_rows.append(k)
            s_cols.append(j)
            s_vals.append(sign)
            continue
        if root not in reduced:
            reduced[root] = len(new_names)
            new_names.append(names[root])
        t_rows.append(k)
        t_cols.append(reduced[root])
    n_red_nodes = len(new_names)
    gone = set(removed)
    branch_rows = [k for k in range(n_nodes, n_full) if k not in gone]
    for k in branch_rows:
        t_rows.append(k)
        t_cols.append(len(new_names))
        new_names.append(names[k])
    n_red = len(new_names)
    T = sp.csc_array((np.ones(len(t_rows)), (t_rows, t_cols)), shape=(n_full, n_red))
    S = sp.csc_array((s_vals, (s_rows, s_cols)), shape=(n_full, B.shape[1]))
    P = sp.csr_array((np.ones(len(t_rows)), (t_cols, t_rows)), shape=(n_red, n_full))
    PA = P @ A
    leftover = PA[:, np.asarray(sorted(gone))]
    if leftover.count_nonzero():  # pragma: no cover - guards the construction above
        raise AssertionError("a removed source current did not cancel")
    if (E @ S).count_nonzero():  # pragma: no cover - supplies at capacitor nodes are kept
        raise AssertionError("a fixed node carries a capacitor")
    E_red = sp.csc_array(P @ E @ T)
    A_red = sp.csc_array(PA @ T)
    B_red = sp.csc_array(P @ (B + A @ S))
    C_red = sp.csr_array(C @ T)
    D_red = sp.csr_array(D + C @ S)
    for matrix in (E_red, A_red, B_red, C_red, D_red):
        matrix.eliminate_zeros()
    return E_red, A_red, B_red, C_red, D_red, new_names, n_red_nodes
