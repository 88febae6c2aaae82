"""Errors the API answers with a status and one line (never a traceback)."""

from __future__ import annotations


class WebError(Exception):
    """A request the server refuses: HTTP ``status`` and a one-line message."""

    status = 422

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        if status is not None:
            self.status = status


class BadSceneError(WebError):
    """The scene, cell or start pose of a request cannot be used (422)."""

    status = 422


class PlantUnavailableError(WebError):
    """The plant cannot be built on this server, e.g. the learned chain is missing (503)."""

    status = 503


class BusyError(WebError):
    """Too many computations queued (503)."""

    status = 503


class OverBudgetError(WebError):
    """A computation ran past its wall-clock budget (504)."""

    status = 504
