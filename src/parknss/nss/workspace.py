"""Recycled large CPU buffers for the fused kernels.

A fresh tensor of tens or hundreds of MB is returned to the operating system when freed
and faulted in page by page when allocated again: about 20 ms per 31 MB on the
development machine, several times the cost of the arithmetic written into it. The fused
kernels therefore take their activation and delta buffers from a small free list and
give them back when done (forward activations: when the autograd node that holds them is
freed). Contents of a taken buffer are undefined.
"""

from __future__ import annotations

import torch
from torch import Tensor


class Workspace:
    """Free buffers matched by (shape, dtype); at most ``keep`` are held."""

    def __init__(self, keep: int = 16) -> None:
        self.keep = keep
        self.free: list[Tensor] = []

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

    def clear(self) -> None:
        self.free.clear()


WORKSPACE = Workspace()
