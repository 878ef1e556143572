"""The corpus of real netlists: accepted / agree / refused, with each refusal's reason.

Runs every file of ``tests/corpus/manifest.json`` through the ngspice-reading
reference (``tests/ngspice_reading.py``) and prints Markdown tables: counts per
project, then one row per distinct refusal or misreading. The README's corpus
table comes from::

    python benchmarks/corpus_table.py

``--details`` also lists every file with its outcome. ``--original-check``
also runs validate's check against ngspice's reading of the original file
(:func:`netlistdyn.spice.validate.check_original`) on every compiled file and counts
its verdicts. Needs ngspice.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tests.ngspice_reading import classify, ngspice_available  # noqa: E402

CORPUS = ROOT / "tests" / "corpus"


def _reason(detail: str) -> str:
    """A refusal without its ``file:line:`` prefix."""
    return re.sub(r"^.*?:\d+: ", "", detail)


def _construct(reason: str) -> str:
    """The reason without the element or subcircuit it names, to group files by construct."""
    return re.sub(r"^(\.subckt )?[^\s:]+: ", "", reason)


def _original_verdict(path: Path) -> str:
    """validate's original-file check on ``path`` with its default outputs: agrees / DISAGREES / not run."""
    from netlistdyn.analysis.eigen import analyze_eigenvalues
    from netlistdyn.circuit.probes import default_probes
    from netlistdyn.formulation.compile import compile_netlist
    from netlistdyn.frontend.parser import parse_file
    from netlistdyn.spice.validate import check_original

    netlist = parse_file(path)
    probes = default_probes(netlist)
    model = compile_netlist(netlist, [p.name for p in probes])
    check = check_original(str(path), netlist, model, probes, analyze_eigenvalues(model.A_sparse))
    if not check.ran:
        return "not run"
    return "agrees" if check.passed else "DISAGREES"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--details", action="store_true", help="list every file")
    parser.add_argument(
        "--original-check", action="store_true", help="also run validate's original-file check"
    )
    args = parser.parse_args(argv)
    if not ngspice_available():
        print("ngspice is not installed (apt-get install ngspice)", file=sys.stderr)
        return 1
    entries = json.loads((CORPUS / "manifest.json").read_text(encoding="utf-8"))["files"]
    per_project: dict[str, Counter] = defaultdict(Counter)
    reasons: dict[str, list[str]] = defaultdict(list)
    rows = []
    verdicts: dict[tuple[str, str], list[str]] = defaultdict(list)
    for entry in entries:
        outcome = classify(CORPUS / entry["file"], tuple(entry.get("ngspice_drop", ())))
        counts = per_project[entry["project"]]
        counts["files"] += 1
        counts[outcome.status] += 1
        if outcome.status in ("agree", "wrong"):
            counts["accepted"] += 1
        if outcome.status in ("refused", "wrong", "no-reference"):
            reasons[f"{outcome.status}: {_construct(_reason(outcome.detail))}"].append(entry["file"])
        rows.append((entry["file"], outcome.status, outcome.states, _reason(outcome.detail)))
        if args.original_check and outcome.status in ("agree", "wrong"):
            verdicts[(outcome.status, _original_verdict(CORPUS / entry["file"]))].append(entry["file"])
    total: Counter = Counter()
    for counts in per_project.values():
        total.update(counts)
    cols = ("files", "accepted", "agree", "refused", "wrong", "no-reference")
    print("| project | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 1) + "|")
    for project in sorted(per_project):
        print(f"| {project} | " + " | ".join(str(per_project[project][c]) for c in cols) + " |")
    print("| **total** | " + " | ".join(f"**{total[c]}**" for c in cols) + " |")
    print()
    print("| outcome: reason | files | example |")
    print("|---|---|---|")
    for reason, files in sorted(reasons.items(), key=lambda kv: (-len(kv[1]), kv[0])):
        text = reason.replace("|", "\\|")
        print(f"| {text} | {len(files)} | `{files[0]}` |")
    if args.original_check:
        print()
        print("| corpus outcome | validate's original-file check | files | example |")
        print("|---|---|---|---|")
        for (status, verdict), files in sorted(verdicts.items()):
            print(f"| {status} | {verdict} | {len(files)} | `{files[0]}` |")
    if args.details:
        print()
        print("| file | outcome | states | detail |")
        print("|---|---|---|---|")
        for file, status, states, detail in rows:
            print(f"| `{file}` | {status} | {states} | {detail.replace('|', '/')} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
