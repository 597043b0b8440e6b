"""The `undertow` command line: one typer app, each command a thin call of a library function.

Known user errors (UndertowError) become one line on stderr and exit code 1; anything else is
a bug and keeps its traceback. Commands live in one module per stage and register on import.
"""

from . import data, export, live, localization, mapping, serve, study, waves  # noqa: F401  (registers)
from ._app import app


def main() -> None:  # pragma: no cover - console entry point
    app()


__all__ = ["app", "main"]
