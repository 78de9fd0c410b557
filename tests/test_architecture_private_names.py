"""No hidden API: a module of ``src/relnav`` never imports a name starting with ``_`` from another
package of relnav (issue 43).

A name with a leading underscore is private to its package: the package may change it without
notice. Inside one first-level package (``relnav.navigation.*``, ``relnav.geometry.*`` …, or a
top-level module such as ``relnav.config``) private names may be shared; across packages the name
must be public. Dunder names (``__version__``) and ``__future__`` imports are allowed.
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "relnav"


def _package(module: str) -> str:
    """First-level package of a dotted ``relnav.…`` module name (``relnav`` for the root)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "relnav"


def _module_name(path: Path) -> str:
    rel = path.relative_to(SRC.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def cross_package_private_imports(path: Path) -> list[str]:
    """``"module: package.name"`` for every private name ``path`` imports from another package
    of relnav (relative imports resolved; imports inside functions included)."""
    me = _module_name(path)
    is_pkg = path.name == "__init__.py"
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level:
            base = me.split(".") if is_pkg else me.split(".")[:-1]
            base = base[: len(base) - (node.level - 1)]
            source = ".".join([*base, *([node.module] if node.module else [])])
        else:
            source = node.module or ""
        if source == "__future__" or not (source == "relnav" or source.startswith("relnav.")):
            continue
        if _package(source) == _package(me):
            continue
        for alias in node.names:
            if _private(alias.name):
                out.append(f"{me}: {source}.{alias.name}")
    return out


def test_no_module_imports_a_private_name_from_another_package():
    found = [hit for f in sorted(SRC.rglob("*.py")) for hit in cross_package_private_imports(f)]
    assert not found, "private names imported across packages:\n" + "\n".join(found)


def test_the_check_sees_a_cross_package_private_import(tmp_path, monkeypatch):
    """The rule itself: a private name across packages is found, within a package it is not,
    relative imports are resolved, dunders and public names pass."""
    root = tmp_path / "relnav"
    (root / "geometry").mkdir(parents=True)
    (root / "navigation" / "startup").mkdir(parents=True)
    bad = root / "navigation" / "startup" / "anchor.py"
    bad.write_text(
        "from relnav.geometry.kdtree import _kd_knn, kd_query\n"
        "from relnav import __version__\n"
        "from ..solver import _private_here\n"
        "from ...geometry.se3 import _hidden\n"
        "def f():\n    from relnav.navigation.solver import _also_fine\n",
        encoding="utf-8",
    )
    monkeypatch.setattr(__import__(__name__), "SRC", root)
    assert cross_package_private_imports(bad) == [
        "relnav.navigation.startup.anchor: relnav.geometry.kdtree._kd_knn",
        "relnav.navigation.startup.anchor: relnav.geometry.se3._hidden",
    ]
