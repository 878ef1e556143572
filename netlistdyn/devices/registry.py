"""The device registry: every element kind's :class:`~netlistdyn.devices.traits.DeviceKind`, by kind.

Each stage looks a device up here instead of branching on its kind: the tree roles of the
graph, the branch laws of the linear and nonlinear formulations, the stamps of the sparse
descriptor system, the ngspice writer and the units. A device family is one module that
exports a :class:`~netlistdyn.devices.traits.Family`; adding a family is one module and one
line in :data:`REGISTRY` (and its tag in :class:`~netlistdyn.circuit.netlist.Kind`).

The registry is immutable: :meth:`Registry.with_family` returns a new one, which the entry
points that take a ``devices`` argument (the formulation, the parser) then use.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from netlistdyn.devices import (
    behavioural,
    controlled,
    coupling,
    diode,
    passive,
    sources,
    storage,
    transformer,
)
from netlistdyn.devices.traits import DeviceKind, Family


@dataclass(frozen=True)
class Registry:
    """Device records by element kind (read-only).

    Attributes
    ----------
    kinds : mapping
        ``Kind`` (or a test's own tag) → :class:`DeviceKind`.
    """

    kinds: MappingProxyType[Any, DeviceKind]

    @classmethod
    def of(cls, *families: Family) -> Registry:
        """The registry of these families; a kind registered twice is an error."""
        kinds: dict[Any, DeviceKind] = {}
        for family in families:
            for record in family.devices:
                if record.kind in kinds:
                    raise ValueError(f"device kind {record.kind} registered twice")
                kinds[record.kind] = record
        return cls(MappingProxyType(kinds))

    def with_family(self, family: Family) -> Registry:
        """A new registry with ``family``'s kinds added (this one is unchanged)."""
        return Registry.of(Family(tuple(self.kinds.values())), family)

    def __getitem__(self, kind: Any) -> DeviceKind:
        return self.kinds[kind]

    def __contains__(self, kind: object) -> bool:
        return kind in self.kinds

    def __iter__(self) -> Iterator[DeviceKind]:
        return iter(self.kinds.values())


#: Every device family of netlistdyn: one line per family module.
REGISTRY = Registry.of(
    passive.FAMILY,
    coupling.FAMILY,
    sources.FAMILY,
    controlled.FAMILY,
    transformer.FAMILY,
    diode.FAMILY,
    behavioural.FAMILY,
    storage.FAMILY,
)


def device(kind: Any) -> DeviceKind:
    """The record of ``kind`` in :data:`REGISTRY`."""
    return REGISTRY[kind]
