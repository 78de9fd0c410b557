"""docs/architecture.md names every module of ``src/relnav`` (issue 43).

The map is only useful while it is complete: a module added without its line fails here. Every
``.py`` file counts except package ``__init__.py`` files (mostly re-exports; the one with the
point-cloud API is listed anyway); private modules (``_name.py``) count too. A module is named by
its path relative to ``src/relnav`` in backquotes, e.g. `` `geometry/kdtree.py` ``.
"""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SRC = REPO / "src" / "relnav"
DOC = REPO / "docs" / "architecture.md"


def named_modules(text: str) -> set[str]:
    """Every backquoted ``….py`` path in ``text``."""
    return set(re.findall(r"`([A-Za-z0-9_/]+\.py)`", text))


def missing_modules(src: Path, text: str) -> list[str]:
    """Module files of ``src`` (``__init__.py`` excepted) that ``text`` does not name."""
    named = named_modules(text)
    files = [p.relative_to(src).as_posix() for p in src.rglob("*.py") if p.name != "__init__.py"]
    return sorted(f for f in files if f not in named)


def test_every_module_is_in_architecture_md():
    missing = missing_modules(SRC, DOC.read_text(encoding="utf-8"))
    assert not missing, f"add one line per module to docs/architecture.md: {missing}"


def test_a_missing_module_is_reported(tmp_path):
    (tmp_path / "geometry").mkdir()
    for name in ("geometry/__init__.py", "geometry/kdtree.py", "geometry/_private.py", "scan.py"):
        (tmp_path / name).write_text("", encoding="utf-8")
    text = "- `geometry/kdtree.py` — the tree.\n- `scan.py`, and geometry/_private.py unquoted\n"
    assert missing_modules(tmp_path, text) == ["geometry/_private.py"]
