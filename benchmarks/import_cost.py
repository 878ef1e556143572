"""What a user pays before every command: the CPU of ``import netlistdyn`` and ``netlistdyn --help``.

Runs each command as a fresh child process, interleaved (``click``, ``netlistdyn``,
``--help``, then again), and measures the CPU time of the whole child
(user + system seconds, ``resource.getrusage(RUSAGE_CHILDREN)`` before and after),
so that a busy machine slows the wall clock but hardly the figures. Prints the
minimum and the median over the runs and the ratio of ``netlistdyn --help`` to
``python -c "import click"`` (the floor any click program pays)::

    python benchmarks/import_cost.py --runs 20

The children run in this checkout's root with it first on ``PYTHONPATH``, so they import this
checkout's package, not an installed copy.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: The commands measured, by label; each is run as ``python <args>``.
COMMANDS: dict[str, list[str]] = {
    "python -c 'import click'": ["-c", "import click"],
    "python -c 'import netlistdyn'": ["-c", "import netlistdyn"],
    "netlistdyn --help": ["-m", "netlistdyn", "--help"],
}


def child_cpu(args: list[str], env: dict[str, str]) -> float:
    """CPU seconds (user + system) of one run of ``python <args>``, the whole child process.

    Parameters
    ----------
    args : list of str
        Arguments after the interpreter.
    env : dict
        The child's environment.

    Returns
    -------
    float
        User plus system CPU time of the child (s).
    """
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, *args], env=env, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    """Measure the commands ``--runs`` times each, interleaved, and print min, median and ratios."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--runs", type=int, default=20, help="runs of each command (default 20)")
    args = parser.parse_args()
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    times: dict[str, list[float]] = {label: [] for label in COMMANDS}
    for command in COMMANDS.values():  # warm the file cache and the bytecode once, unmeasured
        subprocess.run([sys.executable, *command], env=env, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
    for _ in range(args.runs):
        for label, command in COMMANDS.items():
            times[label].append(child_cpu(command, env))
    floor = "python -c 'import click'"
    print(
        f"CPU seconds (user + system of the child), {args.runs} interleaved runs each, "
        f"Python {sys.version.split()[0]}"
    )
    print("| command | min [s] | median [s] | median / click |")
    print("|---|---:|---:|---:|")
    for label, values in times.items():
        ratio = statistics.median(values) / statistics.median(times[floor])
        print(f"| `{label}` | {min(values):.3f} | {statistics.median(values):.3f} | {ratio:.2f} |")
    ratio_min = min(times["netlistdyn --help"]) / min(times[floor])
    print(
        f"netlistdyn --help / import click: {ratio_min:.2f} (min), "
        f"{statistics.median(times['netlistdyn --help']) / statistics.median(times[floor]):.2f} (median)"
    )


if __name__ == "__main__":
    main()
