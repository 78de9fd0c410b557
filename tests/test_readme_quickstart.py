"""The README's Quickstart runs as written (issue 42), checked without running it: every
``relnav`` line names a real subcommand and real options, and every file or folder a line reads
was written by a line before it (running them all takes minutes: done by hand before a release,
see the issue's report)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import typer

from relnav.cli.main import app

README = Path(__file__).resolve().parents[1] / "README.md"


def _quickstart_lines() -> list[list[str]]:
    text = README.read_text(encoding="utf-8")
    section = text.split("\n## Quickstart", 1)[1].split("\n## ", 1)[0]
    lines: list[list[str]] = []
    for block in re.findall(r"```bash\n(.*?)```", section, flags=re.S):
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            if words:
                lines.append(words)
    return lines


def _command(name: str):  # type: ignore[no-untyped-def]
    """The click command of ``relnav NAME`` (typer vendors its own click: duck-typed)."""
    group = typer.main.get_command(app)
    cmd = group.commands.get(name)  # type: ignore[attr-defined]
    assert cmd is not None, f"README Quickstart: no subcommand 'relnav {name}'"
    return cmd


def _parse(words: list[str]) -> tuple[object, dict, list[str]]:
    """The command, its parsed options (name → value) and its positional arguments."""
    assert words[0] == "relnav", words
    cmd = _command(words[1])
    ctx = cmd.make_context(f"relnav {words[1]}", list(words[2:]), resilient_parsing=True)
    positional = [
        w
        for p in cmd.params
        if p.param_type_name == "argument"
        for w in _as_list(ctx.params.get(p.name))
    ]
    return cmd, ctx.params, positional


def _as_list(v: object) -> list[str]:
    if v is None:
        return []
    if isinstance(v, list | tuple):
        return [str(x) for x in v]
    return [str(v)]


def test_quickstart_has_every_workflow() -> None:
    names = [w[1] for w in _quickstart_lines()]
    for sub in ("simulate", "odometry", "evaluate", "compare", "fuse", "track", "export", "view"):
        assert sub in names, f"README Quickstart lacks relnav {sub}"
    exported = {w[w.index("--as") + 1] for w in _quickstart_lines() if w[1] == "export"}
    assert exported == {"rosbag2", "kitti"}


def test_quickstart_commands_and_options_exist() -> None:
    for words in _quickstart_lines():
        cmd = _command(words[1])
        known = {o for p in cmd.params for o in (*p.opts, *p.secondary_opts)}
        for w in words[2:]:
            if w.startswith("-"):
                assert w.split("=", 1)[0] in known, (
                    f"{' '.join(words)}: relnav {words[1]} has no {w}"
                )
        # click itself accepts the line (choices, types, required options)
        cmd.make_context(f"relnav {words[1]}", list(words[2:]), resilient_parsing=False)


def test_quickstart_reads_only_what_an_earlier_line_wrote() -> None:
    written: list[Path] = []
    for words in _quickstart_lines():
        _, params, positional = _parse(words)
        for p in positional:
            if words[1] == "simulate":  # a preset name, not a path
                continue
            path = Path(p)
            assert any(path == w or w in path.parents for w in written), (
                f"{' '.join(words)}: {p} is not written by an earlier Quickstart line"
            )
        for key in ("out", "plot_dir", "json"):
            if params.get(key):
                written.append(Path(str(params[key])))
