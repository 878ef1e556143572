"""The package's layers: every import of netlistdyn code, inside functions too, goes down (or stays
within its own sub-package), so no stage can reach one above it."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "netlistdyn"

#: Sub-packages (and top-level modules) by layer, lowest first; one layer's members may not import
#: each other.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("base",),
    ("circuit",),
    ("devices", "statespace"),
    ("frontend", "formulation"),
    ("analysis",),
    ("simulation",),
    ("spice", "io"),
    ("workflows",),
    ("api", "commandline"),
    ("cli", "__init__"),
    ("__main__",),
)
LEVEL = {name: level for level, names in enumerate(LAYERS) for name in names}


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, imported netlistdyn module) of every import in ``path``, nested ones included."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.level:
            raise AssertionError(f"{path}:{node.lineno}: relative import (write the absolute path)")
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "netlistdyn":
            if node.module == "netlistdyn":
                found += [(node.lineno, f"netlistdyn.{a.name}") for a in node.names]
            else:
                found.append((node.lineno, node.module))
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "netlistdyn"]
    return found


def upward_imports() -> list[str]:
    """Every import that goes sideways within a layer or up, as ``file:line source -> target``."""
    bad = []
    for path in sorted(PACKAGE.rglob("*.py")):
        source = path.relative_to(PACKAGE).with_suffix("").parts[0]
        for line, module in _imports(path):
            parts = module.split(".")
            target = parts[1] if len(parts) > 1 else "__init__"
            if target != source and LEVEL[target] >= LEVEL[source]:
                bad.append(f"{path.relative_to(PACKAGE.parent)}:{line} {source} -> {module}")
    return bad


def test_every_module_belongs_to_a_layer() -> None:
    tops = {p.relative_to(PACKAGE).with_suffix("").parts[0] for p in PACKAGE.rglob("*.py")}
    assert tops <= set(LEVEL), sorted(tops - set(LEVEL))


def test_imports_only_go_down() -> None:
    assert upward_imports() == []


def test_the_check_sees_an_upward_import(tmp_path: Path) -> None:
    """The rule itself: an import from base into io is reported (the test above could not fail without it)."""
    probe = tmp_path / "probe.py"
    probe.write_text("def f():\n    from netlistdyn.io.report import text_report\n")
    assert _imports(probe) == [(2, "netlistdyn.io.report")]
    assert LEVEL["io"] > LEVEL["base"]
