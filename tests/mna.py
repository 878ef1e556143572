"""Independent reference: modified nodal analysis (MNA) of a parsed netlist.

Builds the pencil (G + sC) z = Bu u directly from the element stamps, with
node voltages and the currents of V, L, E, H and transformer ports as
unknowns. It shares nothing with the tree/cotree formulation except the
parser, so agreement between the two is evidence that both are right:

* the finite generalized eigenvalues of (−G, C) are the circuit's natural
  frequencies, whatever tree the compiler picked;
* the transfer function c (G + sC)⁻¹ Bu at a few complex s must equal the
  compiled model's C (sI − A)⁻¹ B + D + s D1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from netlistdyn.circuit.netlist import GROUND, Kind, Netlist


@dataclass
class MNA:
    G: np.ndarray
    C: np.ndarray
    Bu: np.ndarray
    node_index: dict[str, int]
    branch_index: dict[str, int]
    netlist: Netlist

    def finite_eigenvalues(self, limit: float = 1e9) -> np.ndarray:
        """Finite generalized eigenvalues λ of G z + λ C z = 0 (|λ| below ``limit``)."""
        alpha, beta = sla.eig(-self.G, self.C, right=False, homogeneous_eigvals=True)
        finite = np.abs(beta) > np.abs(alpha) / limit
        return alpha[finite] / beta[finite]

    def output_row(self, spec: str, s: complex) -> np.ndarray:
        """Row vector c(s) such that output = c(s) z (+ input terms, see input_term)."""
        n = self.G.shape[0]
        row = np.zeros(n, dtype=complex)
        spec = spec.strip().lower()
        name = spec[2:-1]
        if spec.startswith("v("):
            parts = [p.strip() for p in name.split(",")]
            for node, sign in zip(parts, (1, -1), strict=False):
                node = GROUND if node in ("0", "gnd") else node
                if node != GROUND:
                    row[self.node_index[node]] += sign
            return row
        element = self.netlist.element(name)
        kind = element.kind
        if name in self.branch_index:
            row[self.branch_index[name]] = 1
            return row
        vrow = np.zeros(n, dtype=complex)
        for node, sign in zip(element.nodes, (1, -1), strict=True):
            if node != GROUND:
                vrow[self.node_index[node]] += sign
        if kind is Kind.RESISTOR:
            return vrow / element.value
        if kind is Kind.CAPACITOR:
            return s * element.value * vrow
        if kind is Kind.VCCS:
            crow = np.zeros(n, dtype=complex)
            for node, sign in zip(element.control_nodes, (1, -1), strict=True):
                if node != GROUND:
                    crow[self.node_index[node]] += sign
            return element.value * crow
        if kind is Kind.CCCS:
            row[self.branch_index[element.control_source]] = element.value
            return row
        return row  # independent current source: handled by input_term

    def input_term(self, spec: str) -> np.ndarray:
        m = self.Bu.shape[1]
        term = np.zeros(m)
        spec = spec.strip().lower()
        if spec.startswith("i("):
            element = self.netlist.element(spec[2:-1])
            if element.kind is Kind.ISOURCE:
                term[[e.key for e in self.netlist.sources].index(element.key)] = 1.0
        return term

    def transfer(self, outputs: list[str], s: complex) -> np.ndarray:
        z = np.linalg.solve(self.G + s * self.C, self.Bu.astype(complex))
        rows = np.array([self.output_row(o, s) for o in outputs])
        return rows @ z + np.array([self.input_term(o) for o in outputs])


def build_mna(netlist: Netlist) -> MNA:
    nodes = list(netlist.nodes)
    node_index = {n: i for i, n in enumerate(nodes)}
    branch_names = [
        e.key for e in netlist.elements if e.kind in (Kind.VSOURCE, Kind.INDUCTOR, Kind.VCVS, Kind.CCVS)
    ]
    transformers = [e for e in netlist.elements if e.kind is Kind.TRANSFORMER]
    branch_index = {name: len(nodes) + i for i, name in enumerate(branch_names)}
    extra = len(nodes) + len(branch_names)
    port_index = {}
    for t in transformers:
        port_index[t.key] = (extra, extra + 1)
        extra += 2
    n = extra
    sources = [e.key for e in netlist.sources]
    G = np.zeros((n, n))
    C = np.zeros((n, n))
    Bu = np.zeros((n, len(sources)))

    def idx(node: str) -> int | None:
        return None if node == GROUND else node_index[node]

    def stamp(mat: np.ndarray, a: str, b: str, value: float) -> None:
        ia, ib = idx(a), idx(b)
        if ia is not None:
            mat[ia, ia] += value
        if ib is not None:
            mat[ib, ib] += value
        if ia is not None and ib is not None:
            mat[ia, ib] -= value
            mat[ib, ia] -= value

    def current(row_mat: np.ndarray, a: str, b: str, col: int, gain: float = 1.0) -> None:
        """Current z[col]·gain flows from a through the element to b (leaves a)."""
        ia, ib = idx(a), idx(b)
        if ia is not None:
            row_mat[ia, col] += gain
        if ib is not None:
            row_mat[ib, col] -= gain

    def voltage(row: int, a: str, b: str, gain: float = 1.0) -> None:
        ia, ib = idx(a), idx(b)
        if ia is not None:
            G[row, ia] += gain
        if ib is not None:
            G[row, ib] -= gain

    inductors = {e.key: e for e in netlist.elements if e.kind is Kind.INDUCTOR}
    for e in netlist.elements:
        k = e.kind
        if k is Kind.RESISTOR:
            stamp(G, *e.nodes, 1.0 / e.value)
        elif k is Kind.CAPACITOR:
            stamp(C, *e.nodes, e.value)
        elif k is Kind.INDUCTOR:
            r = branch_index[e.key]
            current(G, *e.nodes, r)
            voltage(r, *e.nodes)
            C[r, r] -= e.value
        elif k is Kind.VSOURCE:
            r = branch_index[e.key]
            current(G, *e.nodes, r)
            voltage(r, *e.nodes)
            Bu[r, sources.index(e.key)] = 1.0
        elif k is Kind.ISOURCE:
            a, b = e.nodes
            if idx(a) is not None:
                Bu[idx(a), sources.index(e.key)] -= 1.0
            if idx(b) is not None:
                Bu[idx(b), sources.index(e.key)] += 1.0
        elif k is Kind.VCVS:
            r = branch_index[e.key]
            current(G, *e.nodes, r)
            voltage(r, *e.nodes)
            voltage(r, *e.control_nodes, -e.value)
        elif k is Kind.VCCS:
            a, b = e.nodes
            for node, sign in ((a, 1.0), (b, -1.0)):
                if idx(node) is not None:
                    for cn, cs in zip(e.control_nodes, (1.0, -1.0), strict=True):
                        if idx(cn) is not None:
                            G[idx(node), idx(cn)] += sign * cs * e.value
        elif k is Kind.CCCS:
            current(G, *e.nodes, branch_index[e.control_source], e.value)
        elif k is Kind.CCVS:
            r = branch_index[e.key]
            current(G, *e.nodes, r)
            voltage(r, *e.nodes)
            G[r, branch_index[e.control_source]] -= e.value
        elif k is Kind.COUPLING:
            a, b = e.coupled
            la, lb = inductors[a].value, inductors[b].value
            mutual = e.value * np.sqrt(abs(la * lb))  # as ngspice, whatever the signs
            C[branch_index[a], branch_index[b]] -= mutual
            C[branch_index[b], branch_index[a]] -= mutual
        elif k is Kind.TRANSFORMER:
            r1, r2 = port_index[e.key]
            p1, n1, p2, n2 = e.nodes
            current(G, p1, n1, r1)
            current(G, p2, n2, r2)
            voltage(r1, p1, n1)
            voltage(r1, p2, n2, -e.value)  # v1 − N v2 = 0
            G[r2, r2] += 1.0
            G[r2, r1] += e.value  # i2 + N i1 = 0
    return MNA(G, C, Bu, node_index, branch_index, netlist)
