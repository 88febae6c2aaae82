"""Data-parallel training steps: one fit's batch split over processes (``train.processes``).

A fit with ``train.processes`` P > 1 cuts each step's batch of windows into P contiguous
shards (sizes differ by at most one; a batch of fewer than P windows uses fewer). Shard 0
is rolled out and backpropagated by the fit's own process, shard r by worker r, a
spawned process holding a copy of the model. Each shard's loss is its part of the whole
batch's (:class:`~parknss.nss.losses.Share`: every masked mean divides the shard's sum by
the whole batch's count; the envelope priors are shard 0's), so the terms add up to the
batch's loss and the gradients to its gradient: the same objective and the same Adam
step as the one-process fit, rounded differently (the sums run in another order). The
gradients are added in rank order, so a fit is the same every time it runs with the same
P; a fit's identity names P when it is not 1 (:func:`parknss.nss.config.fit_identity`).

Per step the fit's process sends the current weights to each worker as one flat vector,
works on shard 0, then adds the workers' gradients into its parameters' ``.grad``; Adam,
the history, validation and the checkpoints stay in the fit's process, so a worker holds
nothing that a resume needs. A worker receives a batch's shard once and keeps it while the
steps train on the same batch (the paper recipe's full batch), and a new one when the
batch changes (the fast recipe's minibatches).

Lifecycle: workers are spawned (a fresh interpreter each, ``train.threads`` torch threads,
SIGINT ignored: the fit decides) when the fit starts and stop when it ends; leaving by an
exception (Ctrl-C, SIGTERM, a divergence) kills them at once; a fit killed outright closes
their pipes and they exit. A worker's error is raised in the fit's process in one line.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time
from typing import Any

import numpy as np
import torch

from parknss.errors import ParknssError
from parknss.nss.batch import Batch
from parknss.nss.config import NSSConfig
from parknss.nss.losses import Share, Targets
from parknss.nss.model import NSSModel
from parknss.nss.step import epoch_loss, local_step


def shard_indices(n: int, processes: int) -> list[torch.Tensor]:
    """The windows of each shard of an n-window batch: contiguous, sizes differing by at
    most one, no empty shard (fewer shards than ``processes`` when n < processes)."""
    return list(torch.arange(n).tensor_split(min(processes, max(n, 1))))


def _flat(tensors) -> np.ndarray:
    """Tensors as one flat vector (what crosses the pipe); :func:`_views` undoes it."""
    return torch.cat([t.detach().reshape(-1) for t in tensors]).numpy()


def _views(flat: np.ndarray, like: list[torch.Tensor]) -> list[torch.Tensor]:
    """``flat`` (:func:`_flat` of tensors shaped as ``like``) cut back into those shapes."""
    sizes = [t.numel() for t in like]
    parts = torch.from_numpy(flat).split(sizes)
    return [v.view_as(t) for v, t in zip(parts, like, strict=True)]


def _batch_doc(batch: Batch) -> dict[str, Any]:
    """A batch as NumPy arrays (what crosses the pipe)."""
    t = batch.targets
    doc = {f.name: getattr(t, f.name).numpy() for f in dataclasses.fields(Targets)}
    return {"x0": batch.x0.numpy(), "u": batch.u.numpy(), "targets": doc,
            "lengths": list(batch.lengths), "stride": batch.stride}


def _batch_of(doc: dict[str, Any]) -> Batch:
    targets = Targets(**{k: torch.from_numpy(v) for k, v in doc["targets"].items()})
    return Batch(torch.from_numpy(doc["x0"]), torch.from_numpy(doc["u"]), targets,
                 doc["lengths"], doc["stride"])


class DataParallelSteps:
    """The training step of a fit over ``processes`` processes (module doc); a context
    manager that owns the workers. Call it as :func:`parknss.nss.step.local_step`."""

    def __init__(self, model: NSSModel, cfg: NSSConfig, processes: int) -> None:
        if processes < 2:
            raise ValueError("a data-parallel step needs at least 2 processes")
        self.model, self.cfg, self.processes = model, cfg, processes
        self._procs: list[Any] = []
        self._conns: list[Any] = []
        self._batch: Batch | None = None  # the batch object the workers hold shards of
        self._shard0: Batch | None = None  # this process's shard of it
        self._shares: list[Share] = []  # each shard's Share
        self._cpu: dict[int, float] = {}  # each worker's CPU time, s, as last reported

    @property
    def worker_cpu_s(self) -> float:
        """The workers' CPU time so far, s (start-up included), as of their last reply."""
        return sum(self._cpu.values())

    def __enter__(self) -> DataParallelSteps:
        import multiprocessing
        import sys

        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
            os.cpu_count() or 1)
        if self.processes > cores:  # runs as asked, but say it will not be faster
            print(f"parknss: note: train.processes {self.processes} > the {cores} CPU "
                  "core(s) this process may use: the processes take turns, and the fit is "
                  "slower than with fewer", file=sys.stderr)
        ctx = multiprocessing.get_context("spawn")
        m = self.model
        init = {"cfg": self.cfg, "normalizer": m.normalizer, "geometry": m.geometry,
                "dtype": m.dtype,
                "state": {k: v.detach().numpy() for k, v in m.state_dict().items()}}
        try:
            for rank in range(1, self.processes):
                here, there = ctx.Pipe()
                proc = ctx.Process(target=_worker, args=(there, init, os.getpid()),
                                   daemon=True, name=f"parknss-dp{rank}")
                with _plain_start_method():
                    proc.start()
                there.close()  # the worker's end lives in the worker only: EOF when it dies
                self._procs.append(proc)
                self._conns.append(here)
        except BaseException:
            self._kill()
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            for conn in self._conns:
                with contextlib.suppress(OSError):
                    conn.send(None)
            for proc in self._procs:
                proc.join(10.0)
        self._kill()

    def _kill(self) -> None:
        for proc in self._procs:
            if proc.is_alive():
                proc.kill()
            proc.join(5.0)
        for conn in self._conns:
            conn.close()
        self._procs, self._conns = [], []

    def _recv(self, rank: int) -> Any:
        try:
            msg = self._conns[rank - 1].recv()
        except (EOFError, OSError):
            code = self._procs[rank - 1].exitcode
            raise ParknssError(
                f"data-parallel worker {rank} exited unexpectedly (exit code {code})"
            ) from None
        if msg[0] == "error":
            raise ParknssError(f"data-parallel worker {rank}: {msg[1]}")
        return msg[1:]

    def _send_batch(self, batch: Batch) -> None:
        """Cut ``batch`` into shards, keep shard 0, hand shards 1.. to their workers."""
        whole = Share.of(batch.targets, first=True)
        self._shares = []
        for rank, idx in enumerate(shard_indices(batch.n, self.processes)):
            share = dataclasses.replace(whole, first=rank == 0)
            self._shares.append(share)
            if rank == 0:
                self._shard0 = batch.select(idx)
            else:
                self._conns[rank - 1].send(("batch", _batch_doc(batch.select(idx)), share))
        self._batch = batch

    def __call__(self, model: NSSModel, batch: Batch, cfg: NSSConfig, step: int
                 ) -> dict[str, float]:
        """One step's forward and backward over all shards (gradients accumulate into
        ``model``'s ``.grad``); the whole batch's loss terms as floats."""
        if batch is not self._batch:  # a new batch (the steps never change one in place)
            self._send_batch(batch)
        assert self._shard0 is not None
        params = list(model.parameters())
        weights = _flat(params)
        busy = range(1, len(self._shares))
        for rank in busy:
            self._conns[rank - 1].send(("step", weights))
        try:
            terms = local_step(model, self._shard0, cfg, step, self._shares[0])
        except Exception:  # (an interrupt ends the fit and its workers: nothing to keep)
            for rank in busy:  # their replies to this step, so the pipes stay in step
                with contextlib.suppress(ParknssError):
                    self._recv(rank)
            raise
        for rank in busy:
            grads, part, self._cpu[rank] = self._recv(rank)
            for k, v in part.items():
                terms[k] = terms.get(k, 0.0) + v
            for p, g in zip(params, _views(grads, params), strict=True):
                if p.grad is None:
                    p.grad = g.clone()
                else:
                    p.grad.add_(g)
        if not np.isfinite(terms["total"]):
            raise ParknssError(f"training diverged at step {step} (loss {terms['total']})")
        return terms


@contextlib.contextmanager
def _plain_start_method():
    """A fit run in a pool worker of the local executor (loky) would hand its workers the
    pool's start method, ``loky``, which a fresh interpreter does not know (their start
    fails in multiprocessing's ``prepare``): start them under ``spawn`` and put the pool's
    method back."""
    import multiprocessing

    before = multiprocessing.get_start_method(allow_none=True)
    if before in (None, "spawn", "fork", "forkserver"):
        yield
        return
    multiprocessing.set_start_method("spawn", force=True)
    try:
        yield
    finally:
        multiprocessing.set_start_method(before, force=True)


def _worker(conn, init: dict[str, Any], parent: int) -> None:
    """One data-parallel worker: hold a shard, roll it out and backpropagate it at the
    weights it is sent, return the gradient and the terms; until the pipe closes."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    cfg: NSSConfig = init["cfg"]
    torch.set_num_threads(cfg.train.threads)
    model = NSSModel(cfg.model, init["normalizer"], init["geometry"]).to(init["dtype"])
    model.load_state_dict({k: torch.from_numpy(v) for k, v in init["state"].items()})
    params = list(model.parameters())
    shard: Batch | None = None
    share: Share | None = None
    while os.getppid() == parent:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        try:
            if msg[0] == "batch":
                shard, share = _batch_of(msg[1]), msg[2]
                continue
            with torch.no_grad():
                for p, w in zip(params, _views(msg[1], params), strict=True):
                    p.copy_(w)
            model.zero_grad(set_to_none=True)
            if shard is None or share is None:
                raise RuntimeError("a step before any batch")
            terms = epoch_loss(model, shard, cfg, share=share)
            terms.total.backward()  # finiteness: the fit's process checks the summed loss
            part = terms.as_floats()
            del terms
            grads = _flat([torch.zeros_like(p) if p.grad is None else p.grad for p in params])
            conn.send(("ok", grads, part, time.process_time()))
        except Exception as exc:  # raised in the fit's process, in one line
            conn.send(("error", f"{type(exc).__name__}: {exc}"))

