"""Recycled large CPU buffers for the fused kernels.

A fresh tensor of tens or hundreds of MB is returned to the operating system when freed
and faulted in page by page when allocated again: about 20 ms per 31 MB on the
development machine, several times the cost of the arithmetic written into it. The fused
kernels therefore take their activation and delta buffers from a small free list and
give them back when done (forward activations: when the autograd node that holds them is
freed). Contents of a taken buffer are undefined.

The per-step loops write into one (B, H) slice of such a buffer per layer and step;
``rows`` hands them out as a list of views made once per buffer, not once per epoch
(12 726 views of the activations take about 24 ms to create, 3 % of a fast epoch).
"""

from __future__ import annotations

import torch
from torch import Tensor


class Workspace:
    """Free buffers matched by (shape, dtype); at most ``keep`` are held."""

    def __init__(self, keep: int = 16, keep_rows: int = 8) -> None:
        self.keep = keep
        self.keep_rows = keep_rows
        self.free: list[Tensor] = []
        self._rows: dict[tuple, list[Tensor]] = {}

    def take(self, shape: tuple[int, ...], dtype: torch.dtype) -> Tensor:
        """A buffer of this shape and dtype (recycled if one is free, else new)."""
        shape = tuple(int(s) for s in shape)
        for i, t in enumerate(self.free):
            if tuple(t.shape) == shape and t.dtype == dtype:
                return self.free.pop(i)
        return torch.empty(shape, dtype=dtype)

    def give(self, t: Tensor) -> None:
        """Return a buffer; the oldest ones are dropped beyond ``keep``."""
        self.free.append(t)
        del self.free[: max(0, len(self.free) - self.keep)]

    def rows(self, t: Tensor) -> list[Tensor]:
        """``t.view(-1, *t.shape[-2:]).unbind(0)`` of a contiguous buffer, cached.

        The cached views hold the buffer's storage, so no other tensor can have its address
        while the entry lives: (address, shape, dtype) identifies the buffer. At most
        ``keep_rows`` buffers are cached (the oldest entry is dropped first)."""
        if not t.is_contiguous() or t.dim() < 2:
            raise ValueError("rows() needs a contiguous buffer of at least 2 dimensions")
        key = (t.data_ptr(), tuple(t.shape), t.dtype)
        hit = self._rows.pop(key, None)
        if hit is None:
            hit = list(t.view(-1, t.shape[-2], t.shape[-1]).unbind(0))
        self._rows[key] = hit  # most recently used last
        while len(self._rows) > self.keep_rows:
            del self._rows[next(iter(self._rows))]
        return hit

    def clear(self) -> None:
        self.free.clear()
        self._rows.clear()


WORKSPACE = Workspace()
