"""The `undertow` typer app and what its commands share: one-line user errors and warnings,
progress bars, JSON output, option types."""

from __future__ import annotations

import functools
import json
import math
import os
import sys
import warnings
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from .._util.plain import json_safe
from ..errors import Terminated, UndertowError
from . import _compile_notice
from ._crash import (
    EXIT_BUG,
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    EXIT_USER,
    bug_line,
    sigterm_as_exception,
)

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    rich_markup_mode="markdown",
    help=(
        "undertow: uncertainty-aware acoustic localization and seafloor mapping for underwater "
        "robots in waves.\n\n"
        "Examples:\n\n"
        "    undertow simulate wave-a0.10-f1.00 --out runs/a10f100 --seed 1\n\n"
        "    undertow info runs/a10f100/log\n\n"
        "    undertow info recording.bag --json\n\n"
    ),
)
evaluate_app = typer.Typer(no_args_is_help=True, help="Evaluate results against ground truth.")
app.add_typer(evaluate_app, name="evaluate")

console = Console()
err = Console(stderr=True)


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    print_warnings([str(message)])


def print_warnings(lines) -> None:
    """One ``warning: ...`` line on stderr per warning (a result's ``warnings``)."""
    for line in lines:
        err.print(f"[yellow]warning:[/] {line}", highlight=False, soft_wrap=True)


@app.callback()
def _setup() -> None:
    """Library warnings (bad rows dropped, units fixed) become one line each on stderr; a
    compilation of undertow's numba kernels is told once, on stderr when it is a terminal."""
    warnings.showwarning = _one_line_warning
    _compile_notices()


@functools.cache  # one listener per process (the app may be called many times in one)
def _compile_notices() -> _compile_notice.CompileNotice:
    return _compile_notice.install(_tell_a_user)


def _tell_a_user(line: str) -> None:
    """A note on stderr for someone watching it (a terminal); nothing in a pipe or a log."""
    if err.is_terminal:
        err.print(f"note: {line}", highlight=False, soft_wrap=True)


def user_errors(fn):
    """Run a command: an UndertowError (or an OSError on a path the user gave) is one line and
    exit status 1; Ctrl-C and SIGTERM remove temporary output (the ``finally`` clauses run on the
    way out) and exit with 130 and 143; any other exception is a bug: one line naming a crash
    report file, exit status 70 (``UNDERTOW_DEBUG=1`` shows the traceback instead)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            with sigterm_as_exception():
                return fn(*args, **kwargs)
        except (UndertowError, OSError) as exc:  # OSError: a missing folder, permissions, disk
            _error_exit(str(exc), EXIT_USER)
        except KeyboardInterrupt:
            _error_exit("interrupted (Ctrl-C); temporary output removed", EXIT_INTERRUPTED)
        except Terminated:
            _error_exit("terminated (SIGTERM); temporary output removed", EXIT_TERMINATED)
        except (typer.Exit, typer.Abort, typer.TyperException):  # typer's own way out
            raise
        except Exception as exc:
            if os.environ.get("UNDERTOW_DEBUG"):
                raise
            _error_exit(bug_line(exc), EXIT_BUG)

    return wrapper


def _error_exit(message: str, code: int) -> None:
    err.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    raise typer.Exit(code) from None


def progress_bar(quiet: bool):
    from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    return Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TimeElapsedColumn(),
        console=err,
        disable=quiet or not err.is_terminal,  # no bar (nor its blank line) in pipes and logs
        transient=True,
    )


def print_json(data) -> None:
    text = json.dumps(json_safe(data), indent=2, allow_nan=False, default=float)
    sys.stdout.write(text + "\n")


def parse_triple(text: str | None, name: str):
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3:
        raise UndertowError(f"{name}: expected three comma-separated numbers, got {text!r}")
    return values


TopicsOption = Annotated[
    Path | None, typer.Option(help="YAML topic map overriding the BlueROV2 defaults.")
]
QuietOption = Annotated[
    bool, typer.Option("--quiet", "-q", help="No progress or summary on stderr.")
]
OverwriteOption = Annotated[
    bool, typer.Option("--overwrite", help="Replace a non-empty output folder.")
]
ConfigOption = Annotated[
    Path | None,
    typer.Option(
        help="Settings YAML with topics / localizer / mapping sections (see docs/command-line.md)."
    ),
]


TimeOption = Annotated[
    str | None,
    typer.Option(
        "--time",
        help="Time base of the log: auto (header stamps when every stream has them on one "
        "clock, else the record time), header or record. Default: the settings' log.time.",
    ),
]

SoundSpeedOption = Annotated[
    float | None,
    typer.Option(
        "--sound-speed",
        metavar="M/S",
        help="The water's sound speed: DVL and sonar ranges and DVL velocities, converted by "
        "the sensors with the speed they were set to (1500 m/s unless the settings' "
        "log.dvl_sound_speed_m_s / sonar_sound_speed_m_s say otherwise), are corrected to it. "
        "Default: the settings' log.sound_speed_m_s or log.water_temperature_c, else none.",
        show_default=False,
    ),
]

InPiecesOption = Annotated[
    bool | None,
    typer.Option(
        "--in-pieces/--whole",
        help="A ROS bag read in pieces of --piece-s seconds (bounded memory) or whole. "
        "Default: in pieces when its index spans more than 2 h or 1.8 million messages, "
        "said in one line (docs/localization.md).",
        show_default=False,
    ),
]
PieceSOption = Annotated[
    float | None,
    typer.Option(
        "--piece-s", metavar="S", help="Seconds of log per piece (600); giving it asks for pieces."
    ),
]


def pieces_option(in_pieces: bool | None, piece_s: float | None) -> dict:
    """``in_pieces`` and ``piece_s`` for ``localize_file`` / ``map_file``: a piece length
    given alone asks for the pieces."""
    if piece_s is None:
        return {"in_pieces": in_pieces}
    return {"in_pieces": True if in_pieces is None else in_pieces, "piece_s": piece_s}


def settings_with_time(config: Path | None, time: str | None, sound_speed: float | None = None):
    """The settings to pass a job: the ``--config`` path as given, or, with ``--time`` or
    ``--sound-speed``, the settings read with their ``log.time`` or ``log.sound_speed_m_s``
    replaced (one line for a bad value; a sound speed given replaces a water temperature)."""
    if time is None and sound_speed is None:
        return config
    from ..io.clock import check_policy
    from ..settings import Settings

    settings = Settings.from_yaml(config)
    update = {} if time is None else {"time": check_policy(time)}
    if sound_speed is not None:
        if not (math.isfinite(sound_speed) and sound_speed > 0):
            raise UndertowError(f"--sound-speed: {sound_speed:g}, expected a speed in m/s > 0")
        update.update(sound_speed_m_s=float(sound_speed), water_temperature_c=None)
    settings.log = settings.log.model_copy(update=update)
    return settings


def fmt_number(value, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"
