"""netlistdyn: compile SPICE-like netlists to linear state-space models.

The Python API mirrors the command line::

    import netlistdyn
    model = netlistdyn.compile("netlists/circuit1.cir", params={"R1": "100"})
    model.A, model.B, model.C, model.D, model.states
    netlistdyn.eigenvalues(model)
    sim = netlistdyn.simulate("netlists/circuit1.cir", tstop="20m")
    sim["v(a)"], sim.time

A netlist is a path, netlist text (a string with a line break) or an open
file; parameters are numbers or SPICE numbers (``"10u"``).
"""

from __future__ import annotations

import sys as _sys
import types as _types
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

# The pipeline stages named like the API's functions are imported first: importing a submodule
# binds it as an attribute of the package, so it must happen before the functions take the names
# (reach the stages by ``from netlistdyn.simulate import ...``).
from . import simulate as _simulate_stage  # noqa: F401
from . import sweep as _sweep_stage  # noqa: F401
from . import validate as _validate_stage  # noqa: F401
from .api import (
    NetlistSource,
    Simulation,
    SimulationError,
    Sweep,
    SweepCase,
    Validation,
    eigenvalues,
    simulate,
    sweep,
    validate,
)
from .errors import ControlDimension, NetlistError, TopologyError, UsageError
from .model import StateSpaceModel

if TYPE_CHECKING:
    from .symbolic import SymbolicModel

__all__ = [
    "ControlDimension",
    "NetlistError",
    "Simulation",
    "SimulationError",
    "StateSpaceModel",
    "Sweep",
    "SweepCase",
    "TopologyError",
    "UsageError",
    "Validation",
    "compile",
    "eigenvalues",
    "simulate",
    "sweep",
    "symbolic",
    "validate",
]
__version__ = "0.1.0"


def compile(
    netlist: NetlistSource,
    params: Mapping[str, Any] | None = None,
    outputs: Sequence[str] | None = None,
    coordinates: Sequence[str] | str | None = None,
) -> StateSpaceModel:
    """Parse and compile a netlist.

    Parameters
    ----------
    netlist : str, path-like or file object
        A path, netlist text (a string with a line break; its first line is
        the title) or an open file such as ``io.StringIO``.
    params : mapping, optional
        ``.param`` overrides: numbers or SPICE numbers (``{"R1": "10u"}``).
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
    from .api import compile_model

    if coordinates is not None:
        from .api import api_errors, read_netlist
        from .coordinates import prepare

        with api_errors(params):
            return prepare(read_netlist(netlist, params), outputs, coordinates).model
    return compile_model(netlist, params, outputs)[1]


def symbolic(
    netlist: NetlistSource,
    params: Mapping[str, Any] | None = None,
    outputs: Sequence[str] | None = None,
    keep: Sequence[str] | None = None,
) -> SymbolicModel:
    """Parse a netlist and compile it with element values as sympy symbols (needs sympy).

    Parameters
    ----------
    netlist : str, path-like or file object
        As :func:`compile`.
    params : mapping, optional
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
    from .api import api_errors, read_netlist
    from .symbolic import symbolic_model

    with api_errors(params):
        return symbolic_model(read_netlist(netlist, params), outputs, keep)


class _Package(_types.ModuleType):
    """The package module, keeping :func:`symbolic` bound to its name.

    The stage ``netlistdyn/symbolic.py`` needs sympy (optional), so it cannot
    be imported eagerly like the other stages named after API functions; when
    it is first imported, Python would bind the submodule over the function.
    The submodule stays reachable as ``netlistdyn.symbolic`` in ``sys.modules``
    (``from netlistdyn.symbolic import symbolic_model`` works).
    """

    def __setattr__(self, name: str, value: object) -> None:
        if name == "symbolic" and isinstance(value, _types.ModuleType) and callable(self.__dict__.get(name)):
            return
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Package
