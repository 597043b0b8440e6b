"""Errors a user can meet. The CLI prints them as one line and exits non-zero.

Library code raises these (never ``print`` + ``sys.exit``); anything else is a bug: the
command line prints one line naming a crash report with the traceback and exits with 70.
"""

from __future__ import annotations


class UndertowError(Exception):
    """Base class of every user-facing error (bad file, bad config, missing data)."""


class ReaderError(UndertowError):
    """A log file could not be read: unreadable, truncated, empty or of an unknown format."""


class MissingStreamError(UndertowError):
    """A stage needs a measurement stream that the log does not contain."""


class ConfigError(UndertowError):
    """A configuration or scenario file is invalid."""


class DataError(UndertowError):
    """Measurement arrays are inconsistent (shapes, time going backwards, non-finite times)."""


class Terminated(BaseException):
    """The process was asked to stop (SIGTERM). Like KeyboardInterrupt it is not an
    ``Exception``, so no ``except Exception`` swallows it, and every ``finally`` on the way out
    runs (temporary output is removed); the command line then exits with 128 + 15."""
