"""The compiled state-space model and what the compiler learned on the way.

``x' = A x + B u``, ``y = C x + D u + D1 u'`` with named states, inputs and
outputs. Matrices are stored sparse (``A_sparse`` ...) and offered dense and
read-only as ``A``, ``B``, ``C``, ``D``, ``D1`` — python-control's names,
with ``nstates``, ``ninputs``, ``noutputs``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from netlistdyn.base.errors import ControlDimension, UsageError
from netlistdyn.base.formatting import Rendered
from netlistdyn.circuit.netlist import Diagnostic
from netlistdyn.statespace.views import model_html, model_latex, model_text


@dataclass(frozen=True, slots=True)
class ExcessElement:
    """A capacitor or inductor that is not a state, and why.

    Attributes
    ----------
    element : str
        Its label.
    reason : str
        ``"capacitor loop"`` (closes a loop of capacitors and voltage-type
        branches) or ``"inductor cutset"`` (lies in a cutset of inductors and
        current-type branches).
    members : tuple of str
        The other elements of that loop or cutset.
    """

    element: str
    reason: str
    members: tuple[str, ...]

    def describe(self) -> str:
        """One sentence for the report."""
        kind = "loop" if self.reason == "capacitor loop" else "cutset"
        what = "capacitors and voltage sources" if kind == "loop" else "inductors and current sources"
        return f"{self.element} is not a state: it closes a {kind} of {what} with {', '.join(self.members)}"


@dataclass(frozen=True, slots=True)
class StateShift:
    """A state redefined to remove an input derivative from its equation.

    The state named ``state`` stands for ``state − Σ coefficients[u] · u``.
    """

    state: str
    coefficients: tuple[tuple[str, float], ...]

    def describe(self) -> str:
        """One sentence for the report."""
        terms = " ".join(f"{'-' if c > 0 else '+'} {abs(c):.6g}·{u}" for u, c in self.coefficients)
        return (
            f"state {self.state} stands for {self.state} {terms} "
            "(this change of variable removes the input derivative from its equation)"
        )


@dataclass(frozen=True)
class CompileInfo:
    """Diagnostics of the compilation.

    Attributes
    ----------
    order : int
        Order of complexity (number of independent capacitor charges and
        inductor currents) = number of states.
    tree : tuple of str
        Branches of the normal tree.
    excess : tuple of ExcessElement
        Capacitors and inductors that are not states.
    shifts : tuple of StateShift
        States redefined to absorb input derivatives.
    warnings : tuple of Diagnostic
        Warnings from parsing and compiling.
    integrators : tuple of str
        Displacement states added because an ``x(...)`` output asked for
        them (not part of the order of complexity).
    passive : bool
        Only positive R, L, C, couplings with |k| < 1, lossless transformers
        and independent sources: the stored energy cannot grow, so no
        eigenvalue has a positive real part.
    """

    order: int
    tree: tuple[str, ...] = ()
    excess: tuple[ExcessElement, ...] = ()
    shifts: tuple[StateShift, ...] = ()
    warnings: tuple[Diagnostic, ...] = ()
    integrators: tuple[str, ...] = ()
    passive: bool = False


@dataclass(frozen=True)
class Pencil:
    """The circuit's own equations, from which A was reduced: G w + E w' = 0 (inputs zero).

    One row per branch law, one column per branch primary (a tree branch's
    voltage, a link's current); the entries are element values (Ω, F, H,
    gains) and the ±1 of the topology. The finite eigenvalues of the pencil
    are the circuit's natural frequencies, so eigenvalues computed from A
    can be checked (and refined) against the element values themselves,
    which covers the error of the reduction to A.

    Attributes
    ----------
    G, E : scipy.sparse.csr_array
        Square matrices of the same size.
    nstates : int
        The pencil's finite eigenvalues are those of the leading
        ``nstates × nstates`` block of A (the remaining states are
        displacement integrators, whose eigenvalues are exactly 0).
    G_data : scipy.sparse.csr_array or None
        The entries of G made of element values (G minus the topology's
        exact ±1); every entry of E is an element value. None: all of G.
    """

    G: sp.csr_array
    E: sp.csr_array
    nstates: int
    G_data: sp.csr_array | None = None


def _readonly(matrix: sp.sparray) -> np.ndarray:
    dense = np.asarray(matrix.toarray(), dtype=float)
    dense.setflags(write=False)
    return dense


@dataclass(frozen=True, repr=False)
class StateSpaceModel(Rendered):
    """A linear time-invariant model with labels.

    Attributes
    ----------
    A_sparse, B_sparse, C_sparse, D_sparse, D1_sparse : scipy.sparse.csr_array
        The matrices; units follow the states (charges in C, currents in A)
        and the inputs (V or A).
    states, inputs, outputs : tuple of str
        Labels, in matrix order.
    title : str
        Netlist title.
    info : CompileInfo
        What the compiler found.
    pencil : Pencil or None
        The circuit equations A was reduced from (set by the compiler, None
        for models built otherwise); eigenvalue analysis checks against it.
    """

    A_sparse: sp.csr_array
    B_sparse: sp.csr_array
    C_sparse: sp.csr_array
    D_sparse: sp.csr_array
    D1_sparse: sp.csr_array
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    title: str = ""
    info: CompileInfo = field(default_factory=lambda: CompileInfo(order=0))
    pencil: Pencil | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        n, m, p = len(self.states), len(self.inputs), len(self.outputs)
        expected = {
            "A": (n, n),
            "B": (n, m),
            "C": (p, n),
            "D": (p, m),
            "D1": (p, m),
        }
        for name, shape in expected.items():
            actual = getattr(self, f"{name}_sparse").shape
            if tuple(actual) != shape:
                raise ControlDimension(
                    f"{name} has shape {tuple(actual)}, expected {shape} "
                    f"for {n} states, {m} inputs, {p} outputs"
                )

    @property
    def nstates(self) -> int:
        """Number of states."""
        return len(self.states)

    @property
    def ninputs(self) -> int:
        """Number of inputs."""
        return len(self.inputs)

    @property
    def noutputs(self) -> int:
        """Number of outputs."""
        return len(self.outputs)

    @cached_property
    def A(self) -> np.ndarray:
        """State matrix, dense and read-only."""
        return _readonly(self.A_sparse)

    @cached_property
    def B(self) -> np.ndarray:
        """Input matrix, dense and read-only."""
        return _readonly(self.B_sparse)

    @cached_property
    def C(self) -> np.ndarray:
        """Output matrix, dense and read-only."""
        return _readonly(self.C_sparse)

    @cached_property
    def D(self) -> np.ndarray:
        """Feedthrough matrix, dense and read-only."""
        return _readonly(self.D_sparse)

    @cached_property
    def D1(self) -> np.ndarray:
        """Feedthrough of input derivatives (y gets D1 u'), dense and read-only."""
        return _readonly(self.D1_sparse)

    @property
    def has_input_derivative(self) -> bool:
        """True when some output depends on an input's derivative."""
        return self.D1_sparse.count_nonzero() > 0

    #: ``repr()``: sizes, labels and (up to 16 states) the labelled matrices, never sparse-array
    #: dumps; HTML; LaTeX.
    RENDERERS = (model_text, model_html, model_latex)

    def to_scipy(self) -> object:
        """``scipy.signal.StateSpace`` of the model (see :func:`to_scipy`)."""
        return to_scipy(self)

    def to_control(self) -> object:
        """``control.StateSpace`` with labels (see :func:`to_control`)."""
        return to_control(self)

    def transfer_function(self, s: complex | ArrayLike) -> np.ndarray:
        """Evaluate G(s) = C (sI − A)⁻¹ B + D + s D1 at complex frequencies.

        Parameters
        ----------
        s : complex or array_like of complex
            Laplace variable (rad/s): one value, or an array of them.

        Returns
        -------
        numpy.ndarray
            For one ``s`` the ``(noutputs, ninputs)`` complex matrix; for an array of shape
            ``(k,)`` the ``(noutputs, ninputs, k)`` array, as python-control's
            ``StateSpace.__call__`` returns it.
        """
        points = np.asarray(s, dtype=complex)
        if points.ndim > 1:
            raise ValueError(f"transfer_function: s must be a scalar or 1-D, not of shape {points.shape}")
        values = np.stack([self._at(complex(z)) for z in points.reshape(-1)], axis=-1)
        return values[:, :, 0] if points.ndim == 0 else values

    def _at(self, s: complex) -> np.ndarray:
        n = self.nstates
        if n:
            resolvent = np.linalg.solve(s * np.eye(n) - self.A, self.B)
            g = self.C @ resolvent
        else:
            g = np.zeros((self.noutputs, self.ninputs), dtype=complex)
        return np.asarray(g + self.D + s * self.D1, dtype=complex)

    def frequency_response(self, omega: ArrayLike) -> FrequencyResponse:
        """G(jω) over angular frequencies, labelled by output and input.

        Parameters
        ----------
        omega : array_like of float
            Angular frequencies (rad/s), 1-D.

        Returns
        -------
        FrequencyResponse
            ``response[i, j, k]`` is G_ij(jω_k); ``magnitude``, ``phase`` (rad) and
            ``frequency_hz`` follow from it.
        """
        w = np.atleast_1d(np.asarray(omega, dtype=float))
        if w.ndim != 1:
            raise ValueError(f"frequency_response: omega must be 1-D, not of shape {w.shape}")
        return FrequencyResponse(w, self.transfer_function(1j * w), self.outputs, self.inputs)


@dataclass(frozen=True)
class FrequencyResponse:
    """A model's frequency response G(jω), with the names of its outputs and inputs.

    Attributes
    ----------
    omega : numpy.ndarray
        Angular frequencies (rad/s), shape ``(k,)``.
    response : numpy.ndarray
        Complex G(jω), shape ``(noutputs, ninputs, k)``.
    outputs, inputs : tuple of str
        Row and column labels.
    """

    omega: np.ndarray
    response: np.ndarray
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]

    @property
    def frequency_hz(self) -> np.ndarray:
        """Frequencies (Hz)."""
        return self.omega / (2 * np.pi)

    @property
    def magnitude(self) -> np.ndarray:
        """|G(jω)| (output unit per input unit)."""
        return np.abs(self.response)

    @property
    def phase(self) -> np.ndarray:
        """arg G(jω) (rad), in (−π, π]."""
        return np.angle(self.response)

    def __call__(self, output: str, input: str) -> np.ndarray:
        """G(jω) of one output/input pair by name, shape ``(k,)``."""
        try:
            return self.response[self.outputs.index(output), self.inputs.index(input)]
        except ValueError:
            raise KeyError(f"no output {output!r} or input {input!r} in this response") from None


def _refuse_input_derivative(model: StateSpaceModel, target: str) -> None:
    """Raise when D1 ≠ 0: a proper state-space object cannot carry y = … + D1 u'."""
    if not model.has_input_derivative:
        return

    rows, cols = np.nonzero(model.D1)
    terms = ", ".join(
        f"{model.outputs[i]} has {model.D1[i, j]:.6g}·d({model.inputs[j]})/dt"
        for i, j in zip(rows.tolist(), cols.tolist(), strict=True)
    )
    raise UsageError(
        f"{target} cannot represent an output that depends on an input's derivative ({terms}); "
        "converting would silently drop that term. Choose other outputs, or use "
        "model.transfer_function(s), which includes s·D1"
    )


def to_scipy(model: StateSpaceModel) -> object:
    """The model as ``scipy.signal.StateSpace`` (labels are not carried by scipy).

    Raises
    ------
    UsageError
        When an output depends on an input's derivative (D1 ≠ 0): scipy's
        proper state-space form has no such term, and dropping it would give a
        different system.
    """
    import scipy.signal as sig  # noqa: PLC0415 (deferred, scipy.signal: 0.6 s of CPU to import)

    _refuse_input_derivative(model, "scipy.signal.StateSpace")
    return sig.StateSpace(np.array(model.A), np.array(model.B), np.array(model.C), np.array(model.D))


def to_control(model: StateSpaceModel) -> object:
    """The model as ``control.StateSpace`` with named states, inputs and outputs.

    Raises
    ------
    ImportError
        When python-control is not installed (``pip install control``).
    UsageError
        When an output depends on an input's derivative (D1 ≠ 0), which
        ``control.StateSpace`` cannot represent.
    """
    _refuse_input_derivative(model, "control.StateSpace")
    try:
        import control  # noqa: PLC0415 (deferred, python-control: optional control extra)
    except ImportError:
        raise ImportError("python-control is not installed: pip install control") from None
    return control.ss(
        np.array(model.A),
        np.array(model.B),
        np.array(model.C),
        np.array(model.D),
        states=list(model.states),
        inputs=list(model.inputs),
        outputs=list(model.outputs),
    )
