"""Progress on stderr for the long commands (tqdm), silent when stderr is not a terminal or with --quiet.

Bars go to stderr so that stdout stays the report; each bar ends its line
when it closes, so nothing printed afterwards lands on the bar's line.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any


def enabled(quiet: bool) -> bool:
    """Whether to show progress: stderr is a terminal and the user did not ask for quiet."""
    return not quiet and sys.stderr.isatty()


@contextmanager
def bar(description: str, total: float | None, quiet: bool = False, unit: str = "it") -> Iterator[Any]:
    """A tqdm bar on stderr (a disabled one when :func:`enabled` is false).

    Parameters
    ----------
    description : str
        What is being done ("sweep", "simulating").
    total : float or None
        Number of steps (None: unknown).
    quiet : bool
        ``--quiet``.
    unit : str
        Name of one step.
    """
    from tqdm import tqdm  # noqa: PLC0415 (deferred, tqdm: only when a bar is made, --help stays light)

    handle = tqdm(
        total=total,
        desc=description,
        unit=unit,
        file=sys.stderr,
        disable=not enabled(quiet),
        leave=True,
        dynamic_ncols=True,
    )
    try:
        yield handle
    finally:
        handle.close()


def fraction_callback(handle: Any) -> Callable[[float], None]:
    """A ``progress(fraction)`` callback that moves a bar of total 100."""

    def show(fraction: float) -> None:
        target = round(100 * min(max(fraction, 0.0), 1.0), 1)
        if target > handle.n:
            handle.update(target - handle.n)

    return show
