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

from netlistdyn.api import compile, eigenvalues, simulate, sweep, symbolic, validate
from netlistdyn.base.errors import ControlDimension, NetlistError, TopologyError, UsageError
from netlistdyn.statespace.model import StateSpaceModel
from netlistdyn.workflows.pipelines import (
    NetlistSource,
    Simulation,
    SimulationError,
    Sweep,
    SweepCase,
    Validation,
)

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
