"""The ``relnav`` command-line tool (Typer + rich).

Each command lives in its own module of :mod:`relnav.cli` exposing ``register(app)``; heavy
imports happen inside the commands so ``relnav --help`` stays fast. Errors that relnav raises
on purpose (:class:`relnav.errors.RelnavError`) are printed as one red line with exit code 1;
``--verbose`` shows the traceback too.
"""

from __future__ import annotations

import importlib
import logging
import sys

import typer
from rich.console import Console
from rich.markup import escape

from relnav import __version__
from relnav.errors import RelnavError

app = typer.Typer(
    name="relnav",
    help="LIDAR-based relative navigation around uncooperative space targets.",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode="rich",
    pretty_exceptions_enable=False,
)
err_console = Console(stderr=True)
_STATE = {"verbose": False}

COMMAND_MODULES = [
    "demo",
    "simulate",
    "export",
    "view",
    "odometry",
    "evaluate",
    "compare",
    "methods",
    "config_cmd",
    "fuse",
    "track",
    "benchmark",
]


def _version(value: bool) -> None:
    if value:
        typer.echo(f"relnav {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Debug logging and tracebacks."),
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """relnav: simulate, estimate, evaluate, report."""
    _STATE["verbose"] = verbose
    from rich.logging import RichHandler

    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.WARNING,
        format="%(message)s",
        handlers=[RichHandler(console=err_console, show_path=False)],
        force=True,
    )
    if not verbose:  # a warning is one line of meaning, not a source location
        import warnings

        def one_line(message, category, filename, lineno, file=None, line=None):  # type: ignore[no-untyped-def]
            err_console.print(f"[yellow]warning:[/] {escape(str(message))}", highlight=False)

        warnings.showwarning = one_line


for _name in COMMAND_MODULES:
    importlib.import_module(f"relnav.cli.{_name}").register(app)


def main() -> None:
    """Console-script entry point."""
    from relnav._threads import limit_blas_threads

    try:
        with limit_blas_threads(1):  # per-process work is small linear algebra: see _threads
            app()
    except RelnavError as e:
        if _STATE["verbose"]:
            err_console.print_exception()
        # escape: messages contain brackets (pip install 'relnav[baselines]') that are not markup
        err_console.print(f"[bold red]error:[/] {escape(str(e))}", highlight=False, soft_wrap=True)
        sys.exit(1)
    except KeyboardInterrupt:
        err_console.print("[yellow]interrupted[/]")
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    main()
