"""The one place where optional dependencies are imported, and their absence explained.

netlistdyn's core needs numpy, scipy, networkx and click; figures, symbolic matrices, Dask,
python-control and PySpice are extras (``pip install 'netlistdyn[plot]'`` ...). :func:`require`
imports one and, when it is missing, raises a :class:`~netlistdyn.base.errors.UsageError` that
names the option that needs it and the command that installs it (one line, exit 2), instead of
a ``ModuleNotFoundError`` after the work is done.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from netlistdyn.base.errors import UsageError

#: Top-level module -> (the pyproject extra that provides it, what ``pip install`` takes alone).
EXTRAS: dict[str, tuple[str, str]] = {
    "matplotlib": ("plot", "matplotlib"),
    "sympy": ("symbolic", "sympy"),
    "dask": ("dask", "'dask[distributed]'"),
    "distributed": ("dask", "'dask[distributed]'"),
    "control": ("control", "control"),
    "PySpice": ("spice", "PySpice"),
}


def install_hint(module: str) -> str:
    """How to install the distribution of ``module``: ``pip install 'netlistdyn[plot]' (or ...)``."""
    top = module.split(".")[0]
    extra, alone = EXTRAS.get(top, (None, top))
    if extra is None:
        return f"pip install {alone}"
    return f"pip install 'netlistdyn[{extra}]' (or pip install {alone})"


def require(module: str, purpose: str) -> ModuleType:
    """Import the optional ``module`` for ``purpose`` (an option such as ``--plot``).

    Raises
    ------
    UsageError
        When it is not installed (or cannot be imported): which option needs it, and how to
        install it.
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        raise missing(module, purpose) from None


def missing(module: str, purpose: str) -> UsageError:
    """The error for an optional ``module`` that ``purpose`` needs and that is not installed."""
    return UsageError(
        f"{purpose} needs {module.split('.')[0]}, which is not installed: {install_hint(module)}"
    )
