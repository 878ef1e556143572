"""Running a function or a program in a child process with a time limit.

Used for ngspice (PySpice's shared mode leaks and cannot be interrupted;
batch ``ngspice -b`` for benchmarks) and for benchmark runs (a stalled
solver must not stall the benchmark).
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import resource
import signal
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
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
    fork = "fork" in multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("fork") if fork else multiprocessing.get_context("spawn")
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
    if how == "timeout":
        proc.kill()  # out of time: stopped now, not after a grace period
    proc.join(timeout=5)
    if proc.is_alive():
        proc.kill()
        proc.join()
    parent.close()
    return result, how


def cpu_seconds() -> float:
    """CPU seconds (user + system) of this process and of its children waited for so far."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@dataclass(frozen=True, slots=True)
class ProgramRun:
    """How a program run by :func:`run_program` ended.

    Attributes
    ----------
    how : str
        "ok" (it exited by itself, whatever its status), "timeout" (killed at
        the time limit), "cpu limit" (stopped at its CPU-seconds limit) or
        "missing" (the program could not be started).
    returncode : int
        Its exit status (negative: killed by that signal).
    stdout, stderr : str
        What it wrote (decoded leniently).
    cpu : float
        User + system CPU time of the child itself (s), from its resource usage.
    wall : float
        Wall time from start to exit (s).
    """

    how: str
    returncode: int
    stdout: str
    stderr: str
    cpu: float
    wall: float


def _die_with_parent(parent: int | None = None) -> None:
    """In the child before exec (Linux): be killed when this process dies, even by SIGKILL.

    Parameters
    ----------
    parent : int, optional
        The pid of the process that started this one, read before the fork. A parent that died
        between the fork and the ``prctl`` (the request only covers a death after it) leaves
        this child orphaned already: it then ends itself instead of running on unattended.
    """
    with contextlib.suppress(Exception):
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    if parent is not None and os.getppid() != parent:
        os._exit(1)


def detached_worker() -> None:
    """Initialiser of a pool worker: its own process group, and killed when its parent dies.

    In its own group a terminal's Ctrl-C reaches the parent alone, which then ends its workers
    (:func:`end_workers`); should the parent be killed outright (SIGKILL, or SIGTERM re-raised
    after the cleanup), the kernel kills the worker too (Linux ``PR_SET_PDEATHSIG``).
    """
    with contextlib.suppress(OSError):
        os.setpgid(0, 0)
    _die_with_parent()


def end_workers(processes: Any) -> None:
    """Kill the worker processes of a pool now (a stopped command must not wait for their tasks).

    ``processes`` is the pool's mapping or sequence of :class:`multiprocessing.Process`.
    """
    members = processes.values() if hasattr(processes, "values") else processes
    for process in list(members or ()):
        with contextlib.suppress(Exception):
            process.kill()
    for process in list(members or ()):
        with contextlib.suppress(Exception):
            process.join(timeout=1.0)


def run_program(
    args: list[str],
    timeout: float | None,
    cwd: str | None = None,
    cpu_limit: float | None = None,
    env: dict[str, str] | None = None,
) -> ProgramRun:
    """Run a program with a time limit and measure its own CPU and wall time.

    The child's resource usage comes from ``wait4`` on that child alone (not
    from all children of this process), so it is exact also for a child
    stopped at the time limit. Its output goes to temporary files (no pipe
    can fill up and stall it).

    Parameters
    ----------
    args : list of str
        The command line.
    timeout : float or None
        Seconds of wall time before the child is killed (it is killed too when this
        process is interrupted or dies).
    cwd : str, optional
        Working directory.
    cpu_limit : float, optional
        CPU seconds the child may use (``RLIMIT_CPU``): a measure that a machine
        shared with other jobs does not stretch, unlike ``timeout``.
    env : dict, optional
        The child's environment (default: this process's).
    """

    parent = os.getpid()

    def prepare() -> None:
        _die_with_parent(parent)
        if cpu_limit is not None:
            resource.setrlimit(resource.RLIMIT_CPU, (int(cpu_limit), int(cpu_limit) + 5))

    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        try:
            proc = subprocess.Popen(args, stdout=out, stderr=err, cwd=cwd, env=env, preexec_fn=prepare)
        except OSError as exc:
            return ProgramRun("missing", -1, "", str(exc), 0.0, 0.0)
        deadline = None if timeout is None else start + timeout
        how, pause, reaped = "ok", 0.001, False
        try:
            while True:
                pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
                if pid:
                    reaped = True
                    break
                now = time.perf_counter()
                if deadline is not None and now >= deadline:
                    how = "timeout"
                    break
                time.sleep(min(pause, deadline - now) if deadline is not None else pause)
                pause = min(pause * 2, 0.05)
        finally:
            if not reaped:  # out of time, or interrupted (Ctrl-C): the program must not outlive us
                with contextlib.suppress(ProcessLookupError):
                    os.kill(proc.pid, signal.SIGKILL)
                pid, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
        cpu = usage.ru_utime + usage.ru_stime
        if how == "ok" and cpu_limit is not None and (proc.returncode < 0 or cpu >= cpu_limit):
            how = "cpu limit"
        out.seek(0)
        err.seek(0)
        return ProgramRun(
            how,
            proc.returncode,
            out.read().decode("utf-8", "replace"),
            err.read().decode("utf-8", "replace"),
            cpu,
            wall,
        )
