"""Sphinx configuration of the netlistdyn documentation.

    python -m sphinx -W --keep-going -b html docs docs/_build/html


The site is Sphinx with MyST Markdown pages, numpydoc for the docstrings, autodoc/autosummary for the
API reference and sphinx-click for the command reference. Every ``docs/*.md`` page is listed by a glob
in ``index.md``, so a page added there appears in the site without editing anything else.
"""

from __future__ import annotations

import pkgutil
import re
import sys
import types
import warnings
from pathlib import Path
from typing import TypeVar

from sphinx.application import Sphinx

# numpydoc reads the docstrings of third-party classes that appear as annotations (sympy's) and warns
# about their unknown sections; those are not this project's docstrings.
warnings.filterwarnings("ignore", message="Unknown section", category=UserWarning)

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

project = "netlistdyn"
author = "the netlistdyn developers"
copyright = "the netlistdyn developers"
release = version = "0.1.0"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "sphinx_click",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "**/.ipynb_checkpoints"]
root_doc = "index"

myst_enable_extensions = ["colon_fence", "dollarmath"]
myst_heading_anchors = 4
# Topic pages written beside the code (docs/*.md) may start at ## or skip a level: that is layout, not
# a broken page, so it is not an error.
suppress_warnings = ["myst.header"]

autosummary_generate = True
autosummary_imported_members = False
autodoc_typehints = "none"
autodoc_member_order = "bysource"
autodoc_default_options = {"show-inheritance": False}
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set[str] = set()

html_theme = "furo"
html_title = "netlistdyn"
html_static_path: list[str] = []


#: An inline literal (````x````) or interpreted text (```x```), inside which nothing is escaped.
_LITERAL = re.compile(r"(``.+?``|`[^`]+`)")


def _escape_bars(app: Sphinx, what: str, name: str, obj: object, options: object, lines: list[str]) -> None:
    """Write the docstrings' ``|x|`` (absolute values, norms) as text, not as reST substitutions.

    Outside inline literals, literal blocks (after ``::``), doctests and tables, a ``|`` is escaped.
    """
    literal_indent: int | None = None
    for k, line in enumerate(lines):
        stripped = line.lstrip()
        indent = len(line) - len(stripped)
        if literal_indent is not None and (not stripped or indent > literal_indent):
            continue
        literal_indent = None
        if stripped.endswith("::"):
            literal_indent = indent
        if stripped == "|" or stripped.startswith(("| ", "+-", "+=", ">>>", "... ")):
            continue
        parts = _LITERAL.split(line)
        lines[k] = "".join(p if i % 2 else p.replace("|", r"\|") for i, p in enumerate(parts))


def _public_objects() -> set[int]:
    """Ids of the objects ``netlistdyn`` exports: the API page documents them under their public name."""
    import netlistdyn

    return {id(getattr(netlistdyn, name)) for name in netlistdyn.__all__}


def _skip(app: Sphinx, what: str, name: str, obj: object, skip: bool, options: object) -> bool | None:
    """Leave type variables out, and public objects out of their defining module's page."""
    if isinstance(obj, TypeVar | types.GenericAlias):
        return True
    if what == "module" and id(obj) in app.config.netlistdyn_public:
        return True
    return None


#: The sub-packages and modules of the API reference, lowest layer first (``api/modules/NAME.rst``).
SUBPACKAGES = (
    "base",
    "circuit",
    "devices",
    "statespace",
    "frontend",
    "formulation",
    "analysis",
    "simulation",
    "spice",
    "io",
    "workflows",
    "api",
    "commandline",
    "cli",
)


def _module_pages(app: Sphinx) -> None:
    """Write one page per public module of the package (``automodule``), a package's page listing its modules.

    Modules whose name starts with ``_`` (generated tables, ``__main__``) are left out.
    """
    import importlib

    out = HERE / "api" / "modules"
    out.mkdir(parents=True, exist_ok=True)
    wanted: set[str] = set()

    def write(name: str) -> None:
        module = importlib.import_module(name)
        children = []
        if hasattr(module, "__path__"):
            children = [
                f"{name}.{info.name}"
                for info in pkgutil.iter_modules(module.__path__)
                if not info.name.startswith("_")
            ]
        lines = [name, "=" * len(name), "", f".. automodule:: {name}", "   :members:", ""]
        if children:
            lines += [".. toctree::", "   :maxdepth: 1", ""] + [f"   {child}" for child in children] + [""]
        text = "\n".join(lines)
        path = out / f"{name}.rst"
        wanted.add(path.name)
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
        for child in children:
            write(child)

    for sub in SUBPACKAGES:
        write(f"netlistdyn.{sub}")
    for stale in out.glob("*.rst"):
        if stale.name not in wanted:
            stale.unlink()


#: A Markdown link ``[text](target)`` (not an image).
_MD_LINK = re.compile(r"(?<!!)\[([^\]]+)\]\(([^)\s]+)\)")


def _outside_links(app: Sphinx, docname: str, source: list[str]) -> None:
    """Write links to Markdown files outside ``docs/`` (``../README.md``) as their text.

    Pages are read on GitHub too, where such links work; the site has no page for those files.
    """
    page_dir = (HERE / docname).parent

    def unlink(match: re.Match[str]) -> str:
        target = match.group(2).split("#")[0]
        if "://" in target or not target.endswith(".md"):
            return match.group(0)
        resolved = (page_dir / target).resolve()
        if resolved.is_relative_to(HERE) or not resolved.exists():
            return match.group(0)
        return f"{match.group(1)} (`{resolved.relative_to(HERE.parent).as_posix()}`)"

    source[0] = _MD_LINK.sub(unlink, source[0])


def _planar_link(app: Sphinx, docname: str, source: list[str]) -> None:
    """Point the planar-mechanisms placeholder at ``docs/planar.md`` when that page exists."""
    if docname != "language/planar":
        return
    if (HERE / "planar.md").exists():
        text = "Planar mechanisms are described on [their own page](../planar.md)."
    else:
        text = "Planar mechanisms are not documented yet: this page will link their page when it exists."
    source[0] = source[0].replace("<!-- planar-link -->", text)


def setup(app: Sphinx) -> None:
    """Connect the docstring filter (before numpydoc's) and the member filter."""
    app.add_config_value("netlistdyn_public", set(), "env")
    app.config.netlistdyn_public = _public_objects()
    app.connect("autodoc-process-docstring", _escape_bars, priority=400)
    app.connect("autodoc-skip-member", _skip)
    app.connect("builder-inited", _module_pages)
    app.connect("source-read", _planar_link)
    app.connect("source-read", _outside_links)
