"""The layer order of docs/architecture.md, checked on the imports of every module.

A module may import its own package and the packages *below* it. The imports that still run
upward are listed in ``KNOWN_UPWARD`` (issue 14 removes them); a new one fails this test, and so
does a listed one that has gone (so that the list stays true).
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "relnav"

LAYERS: list[tuple[str, ...]] = [
    ("relnav", "errors", "scan", "config", "atomic", "_threads"),  # foundations
    ("geometry",),
    ("io",),
    ("sim",),
    ("features",),
    ("matching",),
    ("estimation",),
    ("filtering",),
    ("registration",),
    ("fusion",),
    ("odometry",),
    ("navigation",),
    ("eval",),
    ("pipeline",),
    ("bench",),
    ("cli",),
]
"""Bottom to top; the same order as docs/architecture.md."""

KNOWN_UPWARD: set[tuple[str, str]] = set()
"""(module, imported package) pairs still running upward, to be removed by issue 14 (none left)."""


def _layer(pkg: str) -> int:
    for i, names in enumerate(LAYERS):
        if pkg in names:
            return i
    raise AssertionError(f"package {pkg!r} is not in LAYERS: add it to docs/architecture.md")


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        for n in names:
            parts = n.split(".")
            if parts[0] == "relnav":
                out.add(parts[1] if len(parts) > 1 else "relnav")
    return out


def test_no_module_imports_a_package_above_its_own():
    upward = set()
    for f in SRC.rglob("*.py"):
        rel = f.relative_to(SRC)
        pkg = rel.parts[0] if len(rel.parts) > 1 else rel.stem
        if pkg == "__init__":
            pkg = "relnav"
        for imported in _imports(f):
            if imported != pkg and _layer(imported) > _layer(pkg):
                upward.add((rel.as_posix(), imported))
    new = upward - KNOWN_UPWARD
    assert not new, f"imports running upward (see docs/architecture.md): {sorted(new)}"
    gone = KNOWN_UPWARD - upward
    assert not gone, f"fixed, remove from KNOWN_UPWARD: {sorted(gone)}"


def test_no_module_shadows_the_standard_library():
    """A script run from inside ``src/relnav/...`` has that folder first on ``sys.path``: a module
    named like a standard one (``types.py`` was) would then replace it and break imports.

    The ``io`` *package* is exempt: ``io`` is imported while the interpreter starts, before
    ``sys.path`` is read, so a folder of that name cannot replace it.
    """
    import sys

    names = {p.stem for p in SRC.rglob("*.py") if p.stem != "__init__"}
    names |= {p.name for p in SRC.rglob("*") if p.is_dir() and p.name != "__pycache__"}
    clashes = sorted((names & set(sys.stdlib_module_names)) - {"io"})
    assert not clashes, f"modules named like the standard library: {clashes}"


def test_no_module_is_over_900_lines():
    """One concept per module: a module that grows past 900 lines holds several (issue 14)."""
    long = {
        str(p.relative_to(SRC)): n
        for p in SRC.rglob("*.py")
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > 900
    }
    assert not long, f"modules over 900 lines: {long}"


def test_no_module_names_a_package_above_its_own_in_a_string():
    """An import path in a string (``importlib.import_module("relnav.x.y")``, ``"pkg.mod:Class"``)
    is an import the test above cannot see: it must not point upward either (issue 43: the
    navigator and paper 2's methods were loaded that way from odometry and registration)."""
    import re

    path_like = re.compile(r"^relnav\.(\w+)(\.\w+)*(:\w+)?$")
    upward = set()
    for f in SRC.rglob("*.py"):
        rel = f.relative_to(SRC)
        pkg = rel.parts[0] if len(rel.parts) > 1 else rel.stem
        if pkg == "__init__":
            pkg = "relnav"
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                m = path_like.match(node.value)
                if m and m.group(1) != pkg and _layer(m.group(1)) > _layer(pkg):
                    upward.add((rel.as_posix(), node.value))
    assert not upward, f"import paths in strings running upward: {sorted(upward)}"
