"""netlistdyn: compile SPICE-like netlists to linear state-space models.

The Python API mirrors the command line::

    import netlistdyn
    model = netlistdyn.compile("netlists/circuit1.cir", params={"R1": 100})
    model.A, model.B, model.C, model.D, model.states
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from .errors import ControlDimension, NetlistError, TopologyError, UsageError
from .model import StateSpaceModel

__all__ = [
    "ControlDimension",
    "NetlistError",
    "StateSpaceModel",
    "TopologyError",
    "UsageError",
    "compile",
]
__version__ = "0.1.0"


def compile(
    path: str | Path,
    params: Mapping[str, float] | None = None,
    outputs: Sequence[str] | None = None,
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

    Returns
    -------
    StateSpaceModel
    """
    from .formulate import compile_netlist
    from .parser import parse_file

    return compile_netlist(parse_file(path, params or {}), outputs)
