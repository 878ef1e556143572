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
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    ctx = multiprocessing.get_context(method)
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=target, args=(child, *args), daemon=True)
    proc.start()
    child.close()
    result: Any | None = None
    if parent.poll(timeout):
        with contextlib.suppress(EOFError):
            result = parent.recv()
    proc.join(timeout=5)
    if proc.is_alive():
        proc.kill()
        proc.join()
    return result
