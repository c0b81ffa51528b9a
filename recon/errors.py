"""The one base class for every mistake a user can make.

A ``CoronaryError`` carries a one-line message that names the file, click
or option and what is wrong with it. The command line catches exactly this
class (and nothing broader), prints the message and exits with code 2; the
viewer shows it as a notification. Each pipeline stage raises its own
subclass so that a test or a caller can tell the stages apart.
"""

from __future__ import annotations

__all__ = ["CoronaryError", "LoadError", "OutputError"]


class CoronaryError(ValueError):
    """A user's mistake (bad file, bad click, impossible geometry): a one-line message."""


class LoadError(CoronaryError):
    """An input image or geometry that cannot be used; one line "<file>: <what is wrong>"."""


class OutputError(CoronaryError):
    """An output that cannot be written; one line "<path>: <what is wrong>"."""
