"""Atomic file writes: a temporary file beside the target, then a rename.

A run that fails half way leaves no half-written report, CSV, plot or model.

- The temporary is named ``.<target name>.netlistdyn-<random>.tmp`` in the
  target's folder, so a user who sees one knows where it came from. It is
  removed on every exit path Python can catch: an exception,
  ``KeyboardInterrupt`` (SIGINT) and, once :func:`install_signal_cleanup`
  has run (the command line does it), SIGTERM and SIGHUP. Only SIGKILL (or a
  power cut) can leave it behind — never a partial target.
- A new file gets the mode ``0o666`` minus the umask, as ``open`` would
  give it; an existing file keeps its mode.
- A symbolic link is followed (its target is replaced, the link stays). A
  target that exists but is not a regular file (a FIFO, ``/dev/stdout``, a
  terminal) is written through directly, since it cannot be renamed over.
- ``-`` means standard output.
- Errors (:class:`OSError`) name the user's path, never the temporary.

The set of temporaries in flight is the one piece of process-wide state in
the package: a signal handler can only reach what it can find.
"""

from __future__ import annotations

import contextlib
import os
import signal
import stat
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from types import FrameType

#: Temporaries being written now; removed by the signal handler.
_IN_FLIGHT: set[str] = set()
#: Signals after which temporaries are removed before the process ends.
CLEANUP_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGTERM", "SIGHUP", "SIGINT") if hasattr(signal, name)
)
STDOUT = "-"


def _remove_in_flight() -> None:
    for name in list(_IN_FLIGHT):
        with contextlib.suppress(OSError):
            os.unlink(name)
        _IN_FLIGHT.discard(name)


def _on_signal(signum: int, _frame: FrameType | None) -> None:
    """Remove the temporaries, then die of the same signal (the caller sees how it ended)."""
    _remove_in_flight()
    if signum == getattr(signal, "SIGINT", None):
        raise KeyboardInterrupt
    signal.signal(signum, signal.SIG_DFL)
    os.kill(os.getpid(), signum)


def install_signal_cleanup() -> None:
    """Remove in-flight temporaries on SIGTERM, SIGHUP and SIGINT (main thread only).

    Signals the process ignores (``nohup``) stay ignored.
    """
    for signum in CLEANUP_SIGNALS:
        with contextlib.suppress(ValueError, OSError):  # not the main thread / not allowed
            if signal.getsignal(signum) is not signal.SIG_IGN:
                signal.signal(signum, _on_signal)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def _signals_blocked() -> Iterator[None]:
    """Hold the cleanup signals while a temporary is created and registered."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, CLEANUP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _renamed(exc: OSError, path: str | Path) -> OSError:
    """The same error, naming the user's path."""
    return type(exc)(exc.errno, exc.strerror or str(exc), str(path))


def resolve_target(path: str | Path) -> Path:
    """The file a write to ``path`` replaces: symbolic links followed."""
    return Path(os.path.realpath(path))


def is_stream(path: str | Path) -> bool:
    """True for ``-`` and for existing targets that are not regular files (FIFO, device)."""
    if str(path) == STDOUT:
        return True
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not stat.S_ISREG(mode)


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see the module notes for the rules).

    Parameters
    ----------
    path : str or Path
        Target file, ``-`` for standard output.

    Raises
    ------
    OSError
        With ``filename`` the user's ``path``.
    """
    if str(path) == STDOUT:
        sys.stdout.flush()
        sys.stdout.buffer.write(data)
        sys.stdout.buffer.flush()
        return
    if is_stream(path):
        try:
            with open(path, "wb") as handle:
                handle.write(data)
        except OSError as exc:
            raise _renamed(exc, path) from None
        return
    target = resolve_target(path)
    try:
        mode = stat.S_IMODE(os.stat(target).st_mode)
    except FileNotFoundError:
        mode = 0o666 & ~_umask()
    except OSError as exc:
        raise _renamed(exc, path) from None
    tmp = ""
    try:
        with _signals_blocked():
            fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.netlistdyn-", suffix=".tmp")
            _IN_FLIGHT.add(tmp)
        with os.fdopen(fd, "wb") as handle:
            os.fchmod(handle.fileno(), mode)
            handle.write(data)
        os.replace(tmp, target)
        _IN_FLIGHT.discard(tmp)
        tmp = ""
    except OSError as exc:
        raise _renamed(exc, path) from None
    finally:
        if tmp:
            with _signals_blocked():
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
                _IN_FLIGHT.discard(tmp)


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    write_bytes(path, text.encode())


def check_writable(path: str | Path, option: str) -> str | None:
    """Why ``path`` cannot be written (``None`` when it can), checked before any work.

    Parameters
    ----------
    path : str or Path
        An output file (``-`` is standard output).
    option : str
        The option that named it, for the message.
    """
    if str(path) == STDOUT or is_stream(path):
        return None
    target = resolve_target(path)
    if target.is_dir():
        return f"{option} {path}: is a directory"
    folder = target.parent
    if not folder.is_dir():
        return f"{option} {path}: folder {str(folder)!r} does not exist"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"{option} {path}: folder {str(folder)!r} is not writable"
    return None
