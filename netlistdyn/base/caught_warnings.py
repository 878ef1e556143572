"""Warnings raised inside a command, caught and told in one clean line.

numpy and scipy report floating-point trouble (an overflow in ``exp``, ``inf - inf`` in a product)
as :class:`RuntimeWarning` printed with the library's install path and source line: two stderr
lines a user cannot act on, repeated. :class:`CaughtWarnings` records them instead (each distinct
message once) and :meth:`CaughtWarnings.line` sums them up in one line without paths, which the
command line prints when the command otherwise succeeded (a failed command's own message says
more than the arithmetic that led to it).
"""

from __future__ import annotations

import warnings
from types import TracebackType
from typing import Any

#: Distinct messages kept (a runaway loop warns about the same few operations).
MAX_KEPT = 8


class CaughtWarnings:
    """A context in which warnings are recorded, each distinct message once, instead of printed."""

    def __init__(self) -> None:
        self.messages: dict[tuple[str, str], None] = {}
        self._context = warnings.catch_warnings()

    def __enter__(self) -> CaughtWarnings:
        self._context.__enter__()
        warnings.simplefilter("default")  # once per place: a loop does not call us a million times
        warnings.showwarning = self._record
        return self

    def __exit__(
        self, kind: type[BaseException] | None, value: BaseException | None, trace: TracebackType | None
    ) -> None:
        self._context.__exit__(kind, value, trace)

    def _record(self, message: Warning | str, category: type[Warning], *_: Any, **__: Any) -> None:
        if len(self.messages) < MAX_KEPT:
            self.messages.setdefault((category.__name__, " ".join(str(message).split())), None)

    def line(self) -> str | None:
        """One line for everything caught, or None when nothing was."""
        if not self.messages:
            return None
        numeric = [text for kind, text in self.messages if kind == "RuntimeWarning"]
        other = [f"{kind}: {text}" for kind, text in self.messages if kind != "RuntimeWarning"]
        parts = []
        if numeric:
            parts.append(
                "floating-point trouble on the way (" + "; ".join(numeric) + "): the result is "
                "finite, but check it against an independent run (validate)"
            )
        parts += other
        return "netlistdyn: warning: " + "; ".join(parts)
