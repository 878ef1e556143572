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
    mechanics,
    passive,
    sources,
    storage,
    transformer,
)
from netlistdyn.devices.cards import CardBuilder
from netlistdyn.devices.traits import DeviceKind, Family


@dataclass(frozen=True)
class Registry:
    """Device records by element kind (read-only).

    Attributes
    ----------
    kinds : mapping
        ``Kind`` (or a test's own tag) → :class:`DeviceKind`.
    cards : mapping
        First letter of an element line, or its keyword (lower case) → its builder.
    """

    kinds: MappingProxyType[Any, DeviceKind]
    cards: MappingProxyType[str, CardBuilder]

    @classmethod
    def of(cls, *families: Family) -> Registry:
        """The registry of these families; a kind or card letter registered twice is an error."""
        kinds: dict[Any, DeviceKind] = {}
        cards: dict[str, CardBuilder] = {}
        for family in families:
            for record in family.devices:
                if record.kind in kinds:
                    raise ValueError(f"device kind {record.kind} registered twice")
                kinds[record.kind] = record
            for letter, build in family.cards.items():
                if letter in cards:
                    raise ValueError(f"card letter {letter!r} registered twice")
                cards[letter] = build
        return cls(MappingProxyType(kinds), MappingProxyType(cards))

    def with_family(self, family: Family) -> Registry:
        """A new registry with ``family``'s kinds and cards added (this one is unchanged)."""
        return Registry.of(Family(tuple(self.kinds.values()), dict(self.cards)), family)

    def card(self, word: str) -> CardBuilder | None:
        """The builder of an element line whose first word is ``word``: its keyword's (``MASS``...),
        else its first letter's (None: no family reads it)."""
        low = word.lower()
        return self.cards.get(low) or self.cards.get(low[:1])

    def __getitem__(self, kind: Any) -> DeviceKind:
        return self.kinds[kind]

    def __contains__(self, kind: object) -> bool:
        return kind in self.kinds

    def __iter__(self) -> Iterator[DeviceKind]:
        return iter(self.kinds.values())

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled as its two tables (a compiled formulation crosses to ``sweep --jobs`` workers)."""
        return (_registry, (dict(self.kinds), dict(self.cards)))


def _registry(kinds: dict[Any, DeviceKind], cards: dict[str, CardBuilder]) -> Registry:
    """A registry of these tables (read-only views of them)."""
    return Registry(MappingProxyType(kinds), MappingProxyType(cards))


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
    mechanics.FAMILY,
)


def device(kind: Any) -> DeviceKind:
    """The record of ``kind`` in :data:`REGISTRY`."""
    return REGISTRY[kind]
