"""The one exception family of parknss.

Every error a user can cause (a bad log, a malformed config, a corrupt checkpoint, an
impossible request) is raised as a :class:`ParknssError` whose message is one line naming
the file, the channel and the problem. The CLI prints that line and exits non-zero.
"""

from __future__ import annotations


class ParknssError(Exception):
    """Base class for user-facing errors: the message is the whole story, in one line."""


class DataError(ParknssError):
    """A log, trial or campaign is malformed (missing channel, NaN, wrong rate, ...)."""


class ConfigError(ParknssError):
    """A configuration file is missing, malformed or out of range."""


class CheckpointError(ParknssError):
    """A model artefact is missing, corrupt or does not match the code that loads it."""


class MissingResultsError(ParknssError):
    """A run that may only read stored results (``parknss reproduce --stored-only``) needs
    fits the run cache and the result store do not hold."""

    def __init__(self, desc: str, missing: list[str], total: int) -> None:
        self.desc, self.missing, self.total = desc, list(missing), total
        super().__init__(f"{desc}: {len(self.missing)} of {total} fits are not stored "
                         f"({', '.join(self.missing[:3])}{', ...' if len(missing) > 3 else ''})")


class PlanningError(ParknssError):
    """A scene or planning request is malformed (not: no plan found, which is a result)."""


class ParknssWarning(UserWarning):
    """Something in the input was tolerated; the message is one line (shown by the CLI as
    ``parknss: warning: ...``, without a source location)."""


def show_warnings_as_lines() -> None:
    """Print ParknssWarning as one line ``parknss: warning: MESSAGE`` on stderr (others
    as Python prints them); installed by the command line."""
    import sys
    import warnings

    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if isinstance(category, type) and issubclass(category, ParknssWarning):
            print(f"parknss: warning: {message}", file=file or sys.stderr)
            return
        default(message, category, filename, lineno, file, line)

    if getattr(default, "__name__", "") != "show":
        warnings.showwarning = show


def one_line(exc: BaseException, limit: int = 300) -> str:
    """A foreign exception as ``Type: message`` on one line (whitespace collapsed, cut at
    ``limit`` characters), for the parenthesis of a ParknssError's message."""
    text = " ".join(str(exc).split())
    return f"{exc.__class__.__name__}: {text}"[:limit]
