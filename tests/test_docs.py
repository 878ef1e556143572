"""The documentation: a README that is a front page, and a site that builds without a warning.

The site build is the one ``.ci/run`` makes (``sphinx -W``, then every internal link checked), so a
docstring or a ``docs/*.md`` page that breaks it fails here too, before it reaches CI. It is skipped
when Sphinx and the ``docs`` extra are not installed.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import ROOT

#: The README is a front page: at most this many lines (the rest is in docs/).
README_MAX_LINES = 250
#: The packages of the ``docs`` extra that the site build needs.
DOCS_MODULES = ("sphinx", "myst_parser", "numpydoc", "sphinx_click", "furo")
#: A Markdown link's target: ``[text](target)``.
_LINK = re.compile(r"\]\(([^)\s]+)\)")


def _readme() -> str:
    return (ROOT / "README.md").read_text(encoding="utf-8")


def test_readme_is_a_front_page() -> None:
    text = _readme()
    assert len(text.splitlines()) <= README_MAX_LINES
    lines = text.splitlines()
    # The two commands stay at the very top: install-and-run, then the test command .ci/run runs.
    fences = [
        k for k, line in enumerate(lines[:20]) if line.startswith("pip install") or "pip install" in line
    ]
    assert fences, "the install-and-run command is not at the top of the README"
    assert "python -m pytest" in lines[: fences[0] + 10]
    assert "python -m pytest" in (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()[-1]


def test_readme_links_resolve_and_reach_the_docs_in_one_click() -> None:
    targets = [t for t in _LINK.findall(_readme()) if not re.match(r"^[a-z]+:", t)]
    missing = [t for t in targets if not (ROOT / t.split("#")[0]).exists()]
    assert missing == []
    for page in ("docs/api/index.md", "docs/language/electrical.md", "docs/examples/index.md"):
        assert page in targets


def test_every_docs_page_is_in_the_site() -> None:
    """Pages directly in docs/ are globbed by the index; the sections' pages are listed by name."""
    index = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    assert ":glob:\n\n*\n" in index
    listed = set(re.findall(r"^([a-z]+/[a-z0-9_-]+)$", index, flags=re.M))
    examples = (ROOT / "docs" / "examples" / "index.md").read_text(encoding="utf-8")
    listed |= {f"examples/{name}" for name in re.findall(r"^([a-z0-9_-]+)$", examples, flags=re.M)}
    api = {"api/index"}
    for page in (ROOT / "docs").glob("*/*.*"):
        if page.suffix in (".md", ".rst"):
            name = page.relative_to(ROOT / "docs").with_suffix("").as_posix()
            assert name in listed | api, f"{name} is in no toctree"


@pytest.mark.skipif(
    any(
        importlib.util.find_spec(m) is None
        for m in ("sphinx", "myst_parser", "numpydoc", "sphinx_click", "furo")
    ),
    reason="the docs extra is not installed (pip install -e '.[docs]')",
)
def test_the_site_builds_without_a_warning_and_its_links_resolve(tmp_path: Path) -> None:
    html = tmp_path / "html"
    build = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", "docs", str(html)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    assert build.returncode == 0, build.stderr[-4000:]
    links = subprocess.run(
        [sys.executable, "docs/check_links.py", str(html)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    assert links.returncode == 0, links.stdout[-4000:]
