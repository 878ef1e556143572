"""Running a function in a child process with a time limit.

Used for ngspice (PySpice's shared mode leaks and cannot be interrupted)
and for benchmark runs (a stalled solver must not stall the benchmark).
"""

from __future__ import annotations

import contextlib
import multiprocessing
from collections.abc import Callable
from typing import Any


def run_in_child(target: Callable[..., None], args: tuple[Any, ...], timeout: float | None) -> Any | None:
    """Run ``target(conn, *args)`` in a child and return what it sends, or None.

    Parameters
    ----------
    target : callable
        Called in the child with a pipe end first; it sends one object.
    args : tuple
        Further arguments (inherited through fork where available).
    timeout : float or None
        Seconds to wait before the child is killed.

    Returns
    -------
    object or None
        What the child sent; None when it crashed or ran out of time.
    """
    return run_in_child_status(target, args, timeout)[0]


def run_in_child_status(
    target: Callable[..., None], args: tuple[Any, ...], timeout: float | None
) -> tuple[Any | None, str]:
    """:func:`run_in_child`, also saying how the child ended: "ok", "timeout" or "crashed"."""
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    ctx = multiprocessing.get_context(method)
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=target, args=(child, *args), daemon=True)
    proc.start()
    child.close()
    result: Any | None = None
    how = "timeout"
    if parent.poll(timeout):
        how = "crashed"
        with contextlib.suppress(EOFError):
            result = parent.recv()
            how = "ok"
    proc.join(timeout=5)
    if proc.is_alive():
        proc.kill()
        proc.join()
    parent.close()
    return result, how
