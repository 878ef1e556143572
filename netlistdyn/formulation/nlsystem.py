"""The nonlinear twin of the state-space model: x' = f(x, u(t), t) of a netlist, with its Jacobian.

:class:`NonlinearSystem` evaluates f by solving the network
(:class:`~netlistdyn.formulation.nonlinear.NonlinearCircuit`) for its unknowns at given states; the
transients (:mod:`netlistdyn.simulation.nltransient`), the operating point and the linearisation all
read it.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from netlistdyn.base.errors import NetlistError, SourceLocation
from netlistdyn.circuit.netlist import GROUND, Netlist
from netlistdyn.circuit.sources import SourceValues, resolved_waveforms
from netlistdyn.devices.models import junction_current_array
from netlistdyn.formulation.nonlinear import NonlinearCircuit


class NonlinearSystem:
    """x' = f(x, u(t), t) of a netlist, with its Jacobian.

    Parameters
    ----------
    netlist : Netlist
    span : tuple of float, optional
        (TSTEP, TSTOP) of the transient (s): the SPICE defaults of the source waveforms'
        omitted times (a PULSE's TR, TF = TSTEP, PW, PER = TSTOP). Default: the netlist's
        ``.tran``, else 1 s for both (then only ``f`` at a given input means anything).
    """

    def __init__(self, netlist: Netlist, span: tuple[float, float] | None = None) -> None:
        self.netlist = netlist
        c = self.circuit = NonlinearCircuit(netlist)
        self.waveforms = resolved_waveforms(netlist, span)
        #: u(t): the sources' waveforms (a caller may hold them, as the operating point does).
        self.inputs: Callable[[float], NDArray[np.float64]] = SourceValues(self.waveforms)
        nc, nl, nd = len(c.capacitors), len(c.inductors), len(c.charged_diodes)
        self.nstates = nc + nl + nd + len(c.disp_index)
        self.offsets = (nc, nc + nl)
        # a nonlinear inductor's row of L⁻¹ is 1 here; f() divides it by L(i)
        L = c.inductance_matrix()
        self.Linv = np.linalg.inv(L) if nl else L
        size = c.size
        # P: ∂F/∂x up to sign (F rows of the state-fixed branches), S: f = S z for the linear part
        srows: list[int] = []
        scols: list[int] = []
        svals: list[float] = []
        # a linear capacitor's voltage is q/C (a nonlinear one's moves by dq/C(v), set by jacobian())
        rows, cols, vals = list(c._cap_rows), list(c._cap_states), list(1.0 / c._cap_values)
        for k, e in enumerate(c.capacitors):
            srows.append(k)
            scols.append(c.branch_index[e.key])
            svals.append(1.0)
        for k, e in enumerate(c.inductors):
            rows.append(c.branch_index[e.key])
            cols.append(nc + k)
            vals.append(1.0)
            for j in range(nl):
                g = self.Linv[j, k]
                if g == 0:
                    continue
                for node, sign in ((e.nodes[0], 1.0), (e.nodes[1], -1.0)):
                    if node != GROUND:
                        srows.append(nc + j)
                        scols.append(c.node_index[node])
                        svals.append(sign * g)
        for k, d in enumerate(c.charged_diodes):
            assert d.charge_branch is not None  # charged_diodes are those with a charge branch
            srows.append(nc + nl + k)
            scols.append(d.charge_branch)
            svals.append(1.0)
        for k, (node, index) in enumerate(c.disp_index.items()):  # x(n)' = v(n)
            rows.append(index)
            cols.append(nc + nl + nd + k)
            vals.append(1.0)
            srows.append(nc + nl + nd + k)
            scols.append(c.node_index[node])
            svals.append(1.0)
        self._P_fixed = (rows, cols, vals)
        #: (state index, branch, element) of nonlinear capacitors, and of nonlinear inductors
        self._nl_caps = [
            (k, c.branch_index[e.key], e) for k, e in enumerate(c.capacitors) if e.key in c.storage
        ]
        self._nl_inds = [(nc + k, c.storage[e.key]) for k, e in enumerate(c.inductors) if e.key in c.storage]
        self.S = sp.csr_array((svals, (srows, scols)), shape=(self.nstates, size))
        self.z = np.zeros(size)
        self.stats = {"f": 0, "jac": 0, "newton": 0}
        self._lu = self._fixed_network()

    def _fixed_network(self) -> Any:
        """A factorisation of the state-mode matrix when, states given, the network is linear.

        That is the case when every diode has a charge state (its junction voltage, hence its
        current, is then fixed by the state) and there is no behavioural source: then
        F(z) = G z − b + N with N independent of z, and one LU serves the whole run.
        """
        c = self.circuit
        if c.behavioural or len(c.charged_diodes) != len(c.diodes):
            return None
        G = c.linear_matrix("state")
        try:
            with warnings.catch_warnings():  # an exactly singular matrix: no factorisation to reuse
                warnings.simplefilter("error", scipy.linalg.LinAlgWarning)
                if c.size <= 60:
                    return ("dense", scipy.linalg.lu_factor(G.toarray(), check_finite=True))
                return ("sparse", spla.splu(G.tocsc()))
        except (
            RuntimeError,
            ValueError,
            np.linalg.LinAlgError,
            scipy.linalg.LinAlgError,
            scipy.linalg.LinAlgWarning,
        ):
            return None

    def _solve_fixed(self, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        kind, lu = self._lu
        if kind == "dense":
            return scipy.linalg.lu_solve(lu, rhs)
        return lu.solve(rhs)

    def solve(self, x: NDArray[np.float64], t: float) -> NDArray[np.float64]:
        """The network's unknowns at states ``x`` and time ``t`` (warm-started Newton)."""
        c = self.circuit
        b = c.rhs("state", self.inputs(t), x)
        if self._lu is not None:  # linear given the states: one solve with the run's factorisation
            injected = np.zeros(c.size + 1)
            if c.diodes:
                i, _ = junction_current_array(b[c._qbranch], c._qp)
                np.add.at(injected, c._qa, i)
                np.add.at(injected, c._qk, -i)
            z = self._solve_fixed(b - injected[: c.size])
            if np.all(np.isfinite(z)):
                self.z = z
                return z
        if c.disp_index:  # displacements are given: start there (expressions of them are then exact)
            index = list(c.disp_index.values())
            self.z[index] = b[index]
        z, its, ok = c.newton(self.z, "state", b, t)
        self.stats["newton"] += its
        if not ok:
            z, its, ok = c.newton(np.zeros(c.size), "state", b, t)
            self.stats["newton"] += its
        if not ok:
            raise self._no_solution(t)
        self.z = z
        return z

    def _no_solution(self, t: float) -> NetlistError:
        return NetlistError(
            f"nonlinear transient: the resistive network has no solution at t = {t:.6g} s "
            "(a loop of capacitors, junction capacitances and voltage sources, or a cutset of inductors "
            "and current sources?)",
            SourceLocation(self.netlist.path, 0),
        )

    def f(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """x' (C/s, A/s)."""
        self.stats["f"] += 1
        out = self.S @ self.solve(x, t)
        for k, store in self._nl_inds:  # i' = v / L(i)
            out[k] /= store.value(float(x[k]))[0]
        return out

    def jacobian(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64] | sp.csc_array:
        """∂f/∂x at (t, x): S (∂z/∂x), with J ∂z/∂x = P by implicit differentiation."""
        self.stats["jac"] += 1
        c = self.circuit
        z = self.solve(x, t)
        _, J = c.evaluate(z, "state", c.rhs("state", self.inputs(t), x), t)
        rows, cols, vals = (list(v) for v in self._P_fixed)
        first = self.offsets[1]
        if c.charged_diodes:  # a junction's voltage moves by dq/C(v)
            ext = np.append(z, 0.0)
            _, cap = c.charge_of(ext[c._qa] - ext[c._qk])
            rows += list(c._qbranch)
            cols += list(range(first, first + len(c.charged_diodes)))
            vals += list(1.0 / cap)
        for k, branch, e in self._nl_caps:  # its voltage moves by dq/C(v)
            rows.append(branch)
            cols.append(k)
            vals.append(1.0 / c.charge(e, c._v(z, e.nodes[0]) - c._v(z, e.nodes[1]))[1])
        P = sp.csc_array((vals, (rows, cols)), shape=(c.size, self.nstates))
        try:
            if isinstance(J, np.ndarray):
                jac = np.asarray(self.S @ np.linalg.solve(J, P.toarray()))
            else:
                dz = spla.splu(J.tocsc()).solve(P.toarray())  # one factorisation, every column at once
                jac = np.asarray(self.S @ dz)
        except (np.linalg.LinAlgError, RuntimeError):  # singular: the states are not independent
            raise self._no_solution(t) from None
        if self._nl_inds:  # rows of i' = v / L(i): d/dx (v/L) = (dv/dx)/L − v L'(i)/L² on its own column
            v = self.S @ z
            for k, store in self._nl_inds:
                value, slope = store.value(float(x[k]))
                jac[k] /= value
                jac[k, k] -= v[k] * slope / value**2
        return jac if self.nstates <= DENSE_JACOBIAN else sp.csc_array(jac)

    def outputs(
        self, z: NDArray[np.float64], names: Sequence[str], u: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Output values from the network's unknowns."""
        c = self.circuit
        point = None
        out = np.empty(len(names))
        for k, name in enumerate(names):
            kind, _, rest = name.partition("(")
            args = [a.strip().lower() for a in rest.rstrip(")").split(",")]
            if kind.lower() == "x" and _ground(args[0]) in c.disp_index:
                out[k] = float(z[c.disp_index[_ground(args[0])]])
            elif kind.lower() == "v":
                out[k] = c._v(z, _ground(args[0])) - (c._v(z, _ground(args[1])) if len(args) > 1 else 0.0)
            else:
                if point is None:
                    point = c._point(z, u, 0, 0.0, "state")
                key = args[0]
                if key not in point.currents:
                    raise NetlistError(
                        f"output {name}: no such element current", SourceLocation(self.netlist.path, 0)
                    )
                out[k] = point.currents[key]
        return out


def _ground(node: str) -> str:
    return GROUND if node in ("0", "gnd") else node


#: Largest state count whose Jacobian is handed to the integrator dense (above: sparse, sparse LU).
DENSE_JACOBIAN = 50
