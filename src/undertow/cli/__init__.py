"""The `undertow` command line: one typer app, each command a thin call of a library function.

Known user errors (UndertowError) become one line on stderr and exit code 1; anything else is
a bug and keeps its traceback. Commands live in one module per group and register on import,
in the order `undertow --help` lists them; each calls the library function of the module of
:mod:`undertow.commands` with the same name (``cli/mapping.py`` -> ``commands/mapping.py``).
"""

# importing a module registers its commands, in the order `undertow --help` lists them
# isort: off
from . import data, check, export, live, localization, mapping, serve, study, waves  # noqa: F401

# isort: on
from ._app import app


def main() -> None:  # pragma: no cover - console entry point
    app()


__all__ = ["app", "main"]
