"""``python -m netlistdyn``: the same command line as the ``netlistdyn`` script."""

from __future__ import annotations

from netlistdyn.cli import main

if __name__ == "__main__":  # pragma: no branch
    main(prog_name="netlistdyn")
