"""netlistdyn: compile SPICE-like netlists to linear state-space models.

The Python API mirrors the command line::

    import netlistdyn
    model = netlistdyn.compile("netlists/circuit1.cir", params={"R1": 100})
    model.A, model.B, model.C, model.D, model.states
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import ControlDimension, NetlistError, TopologyError, UsageError
from .model import StateSpaceModel

if TYPE_CHECKING:
    from .symbolic import SymbolicModel

__all__ = [
    "ControlDimension",
    "NetlistError",
    "StateSpaceModel",
    "TopologyError",
    "UsageError",
    "compile",
    "symbolic",
]
__version__ = "0.1.0"


def compile(
    path: str | Path,
    params: Mapping[str, float] | None = None,
    outputs: Sequence[str] | None = None,
    coordinates: Sequence[str] | str | None = None,
) -> StateSpaceModel:
    """Parse and compile a netlist file.

    Parameters
    ----------
    path : str or Path
        Netlist file.
    params : Mapping[str, float], optional
        ``.param`` overrides.
    outputs : sequence of str, optional
        Output specifications (default: every node voltage).
    coordinates : sequence of str or str, optional
        Present the model in these variables (``["x(b1)", "v(b1)", ...]``):
        states named by them, outputs the coordinates unless ``outputs`` is
        given. ``netlistdyn.coordinates.prepare`` also gives T and cond(T).

    Returns
    -------
    StateSpaceModel
    """
    from .formulate import compile_netlist
    from .parser import parse_file

    if coordinates is not None:
        from .coordinates import prepare

        return prepare(parse_file(path, params or {}), outputs, coordinates).model
    return compile_netlist(parse_file(path, params or {}), outputs)


def symbolic(
    path: str | Path,
    params: Mapping[str, float] | None = None,
    outputs: Sequence[str] | None = None,
    keep: Sequence[str] | None = None,
) -> SymbolicModel:
    """Parse a netlist and compile it with element values as sympy symbols.

    Parameters
    ----------
    path : str or Path
        Netlist file.
    params : Mapping[str, float], optional
        ``.param`` overrides (they set the values of elements not in ``keep``).
    outputs : sequence of str, optional
        Output specifications.
    keep : sequence of str, optional
        Element names to keep symbolic; default all.

    Returns
    -------
    SymbolicModel
        ``.A .B .C .D .D1`` as ``sympy.ImmutableMatrix``, the labels, and
        ``.numeric(values)`` to evaluate them.
    """
    from .parser import parse_file
    from .symbolic import symbolic_model

    return symbolic_model(parse_file(path, params or {}), outputs, keep)
