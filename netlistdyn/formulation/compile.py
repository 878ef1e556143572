"""Compile a netlist to its state-space model.

Linearise a nonlinear netlist at its operating point, choose the normal tree, reduce.

The one place where the linear reduction (:mod:`netlistdyn.formulation.formulate`) and the nonlinear
system (:mod:`netlistdyn.formulation.nonlinear`) meet."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from netlistdyn.base.errors import NetlistError, SingularCircuitError, TopologyError
from netlistdyn.circuit.netlist import Netlist
from netlistdyn.circuit.probes import Probe, default_probes, parse_probes
from netlistdyn.devices.registry import REGISTRY, Registry
from netlistdyn.formulation.algebra import NotSupportedError
from netlistdyn.formulation.formulate import (
    OutputDerivativeError,
    check_value_range,
    compile_on_tree,
    tree_candidates,
)
from netlistdyn.formulation.graph import CircuitGraph, TreeSplit
from netlistdyn.formulation.operating import linearised
from netlistdyn.statespace.model import StateSpaceModel


@dataclass(frozen=True)
class Formulation:
    """A compiled netlist with the normal tree that produced it.

    The tree depends only on the topology, so a sweep (:func:`recompile`)
    and the symbolic path (:mod:`netlistdyn.symbolic`) reuse it.
    """

    netlist: Netlist
    circuit: CircuitGraph
    tree: TreeSplit
    probes: tuple[Probe, ...]
    model: StateSpaceModel


def compile_netlist(netlist: Netlist, outputs: Sequence[str] | None = None) -> StateSpaceModel:
    """Compile a parsed netlist to a state-space model.

    Parameters
    ----------
    netlist : Netlist
        Parsed netlist.
    outputs : sequence of str, optional
        Output specifications (``v(n)``, ``v(a,b)``, ``i(elem)``); default:
        every non-ground node voltage.

    Returns
    -------
    StateSpaceModel

    Raises
    ------
    NetlistError
        For inconsistent topologies or singular circuits.
    UsageError
        For output specifications that name unknown nodes or elements.
    """
    return formulate(netlist, outputs).model


def formulate(
    netlist: Netlist, outputs: Sequence[str] | None = None, devices: Registry = REGISTRY
) -> Formulation:
    """Choose the normal tree and compile; see :func:`compile_netlist`.

    Candidate trees are tried in order of decreasing state count: a tree
    that compiles gives the circuit's true order (the reduction is exact), a
    tree with too many states meets a singular capacitance/inductance
    matrix, one with too few meets derivatives it cannot eliminate.
    A nonlinear netlist (diodes, nonlinear behavioural sources) is compiled
    as its linearisation at the DC operating point (:mod:`netlistdyn.nonlinear`).
    ``devices`` is the registry the element kinds are looked up in (a test's own kinds).
    """
    if netlist.planar:  # its exact equations: netlistdyn.formulation.planar, through op/analyze/simulate
        card = netlist.planar[0]
        raise NetlistError(
            f"{card.label}: a planar mechanism is compiled by op, analyze and simulate only "
            "(this command works on circuits and one-dimensional mechanics)",
            card.loc,
        )
    if netlist.is_nonlinear:
        netlist, outputs = linearised(netlist, outputs)
    probes = tuple(parse_probes(outputs, netlist)) if outputs else tuple(default_probes(netlist))
    check_value_range(netlist)
    failure: NetlistError | OutputDerivativeError | None = None
    topology: TopologyError | None = None
    for circuit, tree in tree_candidates(netlist, devices):
        try:
            model = compile_on_tree(netlist, circuit, tree, probes)
        except TopologyError as exc:  # a source loop or cutset: the same on every tree
            topology = topology or exc
            continue
        except (SingularCircuitError, NotSupportedError, OutputDerivativeError) as exc:
            failure = failure or exc
            continue
        return Formulation(netlist, circuit, tree, probes, model)
    error = topology or failure
    assert error is not None
    raise error


def recompile(formulation: Formulation, netlist: Netlist) -> StateSpaceModel:
    """Compile the same circuit with other element values, on the same normal tree.

    Parameters
    ----------
    formulation : Formulation
        A compiled case of the circuit.
    netlist : Netlist
        The circuit again (same elements and nodes), with new values — as
        a sweep produces by re-reading the netlist with other ``.param``
        values.

    Returns
    -------
    StateSpaceModel
        When the topology differs, or the new values make the old tree's
        equations singular, the circuit is compiled from scratch instead.
    """
    old = formulation.netlist.elements
    same = len(old) == len(netlist.elements) and all(
        (a.key, a.kind, a.nodes, a.control_nodes, a.control_source, a.coupled)
        == (b.key, b.kind, b.nodes, b.control_nodes, b.control_source, b.coupled)
        for a, b in zip(old, netlist.elements, strict=True)
    )
    if not same:
        return formulate(netlist, [p.name for p in formulation.probes], formulation.circuit.devices).model
    by_key = {e.key: e for e in netlist.elements}
    circuit = replace(
        formulation.circuit,
        branches=tuple(replace(b, element=by_key[b.element.key]) for b in formulation.circuit.branches),
    )
    try:
        return compile_on_tree(netlist, circuit, formulation.tree, formulation.probes)
    except (SingularCircuitError, NotSupportedError):
        return formulate(netlist, [p.name for p in formulation.probes], formulation.circuit.devices).model
