"""Validate every netlist in netlists/ against ngspice and print a Markdown table.

    python benchmarks/validate_all.py

Each row: the worst output error relative to its peak, ngspice's settings
and both run times (seconds, this machine).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    print("| netlist | passed | worst error / peak | ngspice [s] | model [s] | ngspice method |")
    print("|---|---|---:|---:|---:|---|")
    for path in sorted((ROOT / "netlists").glob("*.cir")):
        proc = subprocess.run(
            [sys.executable, "-m", "netlistdyn.cli", "validate", str(path), "--format", "json", "--no-pz"],
            capture_output=True,
            text=True,
            check=False,
        )
        doc = json.loads(proc.stdout)
        worst = max(o["max_rel_error"] for o in doc["comparisons"])
        method = doc["ngspice"]["settings"].split("method=")[1].split()[0]
        print(
            f"| {path.name} | {doc['passed']} | {worst:.2g} | {doc['ngspice']['seconds']:.3f} "
            f"| {doc['model_seconds']:.3f} | {method} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
