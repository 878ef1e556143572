"""Real netlists written by others, judged against ngspice's own reading.

Each file of ``tests/corpus/manifest.json`` is run through
:func:`tests.ngspice_reading.classify`: an MNA pencil built from ngspice's
expanded listing of the file (checked against ngspice's own op and ac output)
against netlistdyn's model, eigenvalues and transfer values at three complex
frequencies to 1e-6. The manifest records what each file is expected to do:

* ``agree`` — compiled, and every number matches;
* ``refused`` — netlistdyn refuses it with a one-line ``file:line: message``
  (the manifest's ``reason`` says which construct); when the parser learns the
  construct, the test fails and says to move the file to ``agree``;
* ``wrong`` — a known misreading (strict xfail: fixed, it fails until moved).

A wrong number is never accepted for a file expected to agree or be refused.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from .ngspice_reading import classify, ngspice_available

CORPUS = Path(__file__).parent / "corpus"
MANIFEST = json.loads((CORPUS / "manifest.json").read_text(encoding="utf-8"))
ENTRIES = MANIFEST["files"]
ONE_LINE_REFUSAL = re.compile(r"^\S.*:\d+: \S.*$")

needs_ngspice = pytest.mark.skipif(not ngspice_available(), reason="ngspice is not installed")


def test_manifest_is_complete() -> None:
    """Every corpus file is in the manifest with its origin; at least 60 files from 5 projects."""
    listed = {e["file"] for e in ENTRIES}
    on_disk = {
        str(p.relative_to(CORPUS))
        for p in CORPUS.rglob("*")
        if p.is_file() and p.name not in ("manifest.json", "README.md")
    }
    assert listed == on_disk
    assert len(ENTRIES) >= 60
    assert len({e["project"] for e in ENTRIES}) >= 5
    for e in ENTRIES:
        assert {"project", "repository", "path", "commit", "licence", "expect"} <= e.keys(), e["file"]
        assert re.fullmatch(r"[0-9a-f]{40}", e["commit"]), e["file"]
        assert e["expect"] in ("agree", "refused", "wrong"), e["file"]
        if e["expect"] != "agree":
            assert e.get("reason"), f"{e['file']}: an expected refusal or misreading needs its reason"


@needs_ngspice
@pytest.mark.parametrize("entry", ENTRIES, ids=[e["file"] for e in ENTRIES])
def test_corpus_file(entry: dict) -> None:
    outcome = classify(CORPUS / entry["file"], tuple(entry.get("ngspice_drop", ())))
    expect = entry["expect"]
    if outcome.status == "no-reference":
        pytest.fail(f"no reference from ngspice's reading: {outcome.detail}")
    if expect == "wrong":
        if outcome.status == "wrong":
            pytest.xfail(f"known misreading ({entry['reason']}): {outcome.detail}")
        pytest.fail(f"no longer misread ({outcome.status}: {outcome.detail}); update the manifest")
    assert outcome.status != "wrong", f"wrong number: {outcome.detail}"
    if expect == "agree":
        assert outcome.status == "agree", f"expected to agree, got {outcome.status}: {outcome.detail}"
    else:
        assert outcome.status == "refused", (
            f"now accepted and agrees with ngspice ({outcome.detail}): move it to 'agree' in the manifest"
        )
        assert ONE_LINE_REFUSAL.match(outcome.detail), (
            f"refusal is not 'file:line: message': {outcome.detail!r}"
        )
