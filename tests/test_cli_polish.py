"""Issue 42's CLI polish: did-you-mean, full-width tables off a terminal, printed paths."""

from __future__ import annotations

import pytest

from relnav.config import check_options, did_you_mean
from relnav.errors import ConfigError


def test_did_you_mean_offers_the_three_nearest_names_only():
    names = [f"opt_{i}" for i in range(200)] + ["max_points", "max_map_points", "min_points"]
    hint = did_you_mean("max_pointz", names)
    assert hint.startswith(" (did you mean 'max_points'")
    assert hint.count("'") == 6  # three names
    assert did_you_mean("zzzz", names) == ""
    assert did_you_mean("max_itr", ["max_iter", "gate"]) == " (did you mean 'max_iter'?)"


def _many(*, max_points: int = 1, max_map_points: int = 2, min_points: int = 3) -> None:
    """A target with many options (the navigator has ~100)."""


def test_unknown_option_message_is_short_with_many_options():
    import inspect

    params = [
        inspect.Parameter(f"option_{i:03d}", inspect.Parameter.KEYWORD_ONLY, default=0)
        for i in range(120)
    ]

    def target(**kw):  # signature set below: 120 keyword options + 3 near names
        pass

    base = list(inspect.signature(_many).parameters.values())[:3]
    target.__signature__ = inspect.Signature(base + params)
    with pytest.raises(ConfigError) as e:
        check_options(target, {"max_pointz": 100}, where="method 'x'")
    msg = str(e.value)
    assert "did you mean 'max_points', 'max_map_points' or 'min_points'?" in msg
    assert "123 options accepted" in msg and "option_050" not in msg
    assert len(msg) < 200 and "\n" not in msg
    with pytest.raises(ConfigError) as e:
        check_options(_many, {"zzz": 1}, where="m")  # few options: all of them listed
    assert "accepted: max_map_points, max_points, min_points" in str(e.value)


def test_tables_are_full_width_when_stdout_is_not_a_terminal(monkeypatch):
    import io

    from rich.table import Table

    from relnav.cli._common import PIPE_WIDTH, CliConsole

    monkeypatch.delenv("COLUMNS", raising=False)
    table = Table()
    for i in range(12):
        table.add_column(f"kiss-icp-method-{i}")
    table.add_row(*(f"{1.8812345e-05 * (i + 1):.6e}" for i in range(12)))
    buf = io.StringIO()
    con = CliConsole(file=buf)
    assert not con.is_terminal and con.width == PIPE_WIDTH
    con.print(table)
    text = buf.getvalue()
    assert "…" not in text and "1.881234e-05" in text and "kiss-icp-method-11" in text
    # COLUMNS or an explicit width still decide
    monkeypatch.setenv("COLUMNS", "80")
    assert CliConsole(file=io.StringIO()).width == 80
    assert CliConsole(file=io.StringIO(), width=100).width == 100


def test_piped_cli_table_is_not_cut(tmp_path):
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    r = subprocess.run(
        [sys.executable, "-m", "relnav.cli.main", "methods"],
        capture_output=True,
        text=True,
        env=env,
        stdin=subprocess.DEVNULL,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    assert "…" not in r.stdout
    assert "constant-velocity filter of pose and velocity as the prior" in r.stdout
