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

import importlib
from typing import TYPE_CHECKING, Any

from netlistdyn.base.errors import ControlDimension, NetlistError, TopologyError, UsageError

if TYPE_CHECKING:  # the same objects as __getattr__ gives (the API module re-exports the classes)
    from netlistdyn.api import (
        NetlistSource,
        Simulation,
        SimulationError,
        StateSpaceModel,
        Sweep,
        SweepCase,
        Validation,
        compile,
        eigenvalues,
        simulate,
        sweep,
        symbolic,
        validate,
    )

#: The public names loaded on first use (PEP 562), by the module that defines them: ``import netlistdyn``
#: (and so every ``netlistdyn`` command, ``--help`` included) then loads no numpy, scipy or networkx.
_LAZY = {
    "compile": "netlistdyn.api",
    "eigenvalues": "netlistdyn.api",
    "simulate": "netlistdyn.api",
    "sweep": "netlistdyn.api",
    "symbolic": "netlistdyn.api",
    "validate": "netlistdyn.api",
    "StateSpaceModel": "netlistdyn.statespace.model",
    "NetlistSource": "netlistdyn.workflows.pipelines",
    "Simulation": "netlistdyn.workflows.pipelines",
    "SimulationError": "netlistdyn.workflows.pipelines",
    "Sweep": "netlistdyn.workflows.pipelines",
    "SweepCase": "netlistdyn.workflows.pipelines",
    "Validation": "netlistdyn.workflows.pipelines",
}

__all__ = [
    "ControlDimension",
    "NetlistError",
    "NetlistSource",
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


def __getattr__(name: str) -> Any:
    """A public name of :data:`_LAZY`, imported from its module on first use and then cached here."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The module's names, the lazy public ones included."""
    return sorted({*globals(), *__all__})
