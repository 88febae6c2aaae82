"""A machine without a C compiler, for the tests of what builds C through parknss.cbuild."""

from __future__ import annotations

import contextlib


@contextlib.contextmanager
def no_c_compiler(monkeypatch, tmp_path, *cached):
    """No compiler on PATH (CC empty) and an empty build cache under ``tmp_path``; the
    ``functools.cache``'d builders ``cached`` are cleared on entry and on exit, so neither
    a library built before nor the failure leaks into other tests."""
    monkeypatch.setenv("PARKNSS_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "")
    monkeypatch.setenv("PATH", str(tmp_path))
    for f in cached:
        f.cache_clear()
    try:
        yield
    finally:
        for f in cached:
            f.cache_clear()
