"""Parser time on the large valid inputs of issue #12 (quadratic before, linear now).

Prints a Markdown table of the median seconds of ``parse_text`` on each input
at a base size n and at 2n, 4n (a linear parser doubles its time)::

    python benchmarks/bench_parse.py [--repeats 3]

Inputs: one ``.param`` line of n chained assignments ``p_k={p_(k-1)+1}``;
one ``.param`` line of n constant assignments; a PWL source written on n
``+`` continuation lines; a subcircuit bomb (9 levels × 10 instances,
refused by counting before expansion).
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import time
from collections.abc import Callable

from netlistdyn.base.errors import NetlistError
from netlistdyn.frontend.parser import parse_text


def chained(n: int) -> str:
    assigns = " ".join(f"p{k}={{p{k - 1}+1}}" for k in range(1, n))
    return f"chained\n.param p0=1 {assigns}\nV1 a 0 {{p{n - 1}}}\nR1 a 0 1\n"


def constants(n: int) -> str:
    return (
        "constants\n.param " + " ".join(f"p{k}={k}" for k in range(n)) + f"\nV1 a 0 {{p{n - 1}}}\nR1 a 0 1\n"
    )


def continuations(n: int) -> str:
    return "cont\nV1 a 0 PWL(0 0\n" + "".join(f"+ {k + 1}u {k % 2}\n" for k in range(n)) + "+ )\nR1 a 0 1\n"


def bomb(levels: int) -> str:
    body = "".join(
        f".subckt s{k} a b\n" + "".join(f"X{j} a b s{k - 1}\n" for j in range(10)) + ".ends\n"
        for k in range(1, levels + 1)
    )
    return f"bomb\nV1 a 0 1\n.subckt s0 a b\nR1 a b 1\n.ends\n{body}X1 a 0 s{levels}\n"


def median_seconds(text: str, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        with contextlib.suppress(NetlistError):
            parse_text(text)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cases: list[tuple[str, Callable[[int], str], int]] = [
        (".param, chained assignments", chained, 20_000),
        (".param, constant assignments", constants, 20_000),
        ("+ continuation lines (PWL)", continuations, 80_000),
        ("subcircuit bomb, levels (refused)", bomb, 9),
    ]
    print("| input | n | s (n) | s (2n) | s (4n) |")
    print("|---|---:|---:|---:|---:|")
    for label, make, n in cases:
        if make is bomb:
            row = [median_seconds(make(n), args.repeats)]
            print(f"| {label} | {n} | {row[0]:.3f} | | |")
            continue
        row = [median_seconds(make(n * f), args.repeats) for f in (1, 2, 4)]
        print(f"| {label} | {n} | " + " | ".join(f"{t:.2f}" for t in row) + " |")


if __name__ == "__main__":
    main()
