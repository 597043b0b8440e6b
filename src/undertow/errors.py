"""Errors a user can meet. The CLI prints them as one line and exits non-zero.

Library code raises these (never ``print`` + ``sys.exit``); anything else is a bug and keeps
its traceback.
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
