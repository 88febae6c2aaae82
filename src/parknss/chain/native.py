"""The generated C step of a chain, compiled by the system C compiler and called through ctypes.

:class:`NativeChain` has the interface of :class:`~parknss.chain.realtime.RealtimeChain`
(``start``, ``step``, ``gear``, ``dt``) and runs the C of :mod:`parknss.chain.ccode`: the
same arithmetic as the NumPy twin (the reference implementation, which stays the default
of :class:`~parknss.chain.deployed.DeployedChain`), equal to it to rounding, several times
faster. :meth:`NativeChain.run` replays a whole command history in one C call;
:func:`step_many` steps several chains of one artefact (a vector environment's plants)
one sample in one C call, each NSS layer applied to all of them at once.

:func:`parknss.cbuild.compile_library` builds and caches the shared library (``-march=native``:
this machine's vector instructions; C99 keeps the compiler from contracting a multiply and an
add into one rounding, and the vector code uses basic IEEE operations only, so the result is
the portable build's bit for bit, tests/chain/test_native.py). The FMU's binary is built
portable (:data:`~parknss.cbuild.CFLAGS`).
"""

from __future__ import annotations

import ctypes

import numpy as np

from parknss.cbuild import NATIVE_FLAGS, compile_library
from parknss.chain.ccode import OUTPUTS, chain_c_source
from parknss.chain.realtime import RealtimeChain
from parknss.errors import ParknssError

_DOUBLE_P = ctypes.POINTER(ctypes.c_double)


class NativeChain:
    """A chain's generated C step through ctypes (the interface of RealtimeChain), built
    with ``flags`` (default: for this machine; :data:`CFLAGS`: the FMU's portable build)."""

    def __init__(self, rt: RealtimeChain, flags: tuple[str, ...] = NATIVE_FLAGS) -> None:
        self.dt = rt.dt
        self.path = compile_library(chain_c_source(rt).files(), flags)
        lib = ctypes.CDLL(str(self.path))
        lib.pk_size.restype = ctypes.c_size_t
        for fn in (lib.pk_start, lib.pk_step, lib.pk_run, lib.pk_step_many):
            fn.restype = None
        lib.pk_start.argtypes = [ctypes.c_void_p, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P]
        lib.pk_run.argtypes = [ctypes.c_void_p, _DOUBLE_P, ctypes.c_long, _DOUBLE_P]
        lib.pk_step_many.argtypes = [ctypes.c_void_p, ctypes.c_long, ctypes.c_void_p,
                                     ctypes.c_void_p]
        self._lib = lib
        self._state = ctypes.create_string_buffer(lib.pk_size())
        self._addr = ctypes.addressof(self._state)  # what pk_step_many's state array holds
        self._cmd = (ctypes.c_double * 4)()
        self._out = (ctypes.c_double * len(OUTPUTS))()
        # pk_step through its own handle without argtypes: the pointers are passed as
        # ready c_void_p, so a call converts nothing
        self._step = ctypes.CDLL(str(self.path)).pk_step
        self._step.restype = None
        self._args = tuple(ctypes.c_void_p(ctypes.addressof(b))
                           for b in (self._state, self._cmd, self._out))
        self.gear = 0.0

    def start(self, x0, y0, cmd0) -> None:
        """As :meth:`RealtimeChain.start`: x0 [vx, yaw], actuals y0, first command cmd0."""
        arr = [(ctypes.c_double * n)(*map(float, v)) for n, v in ((2, x0), (3, y0), (4, cmd0))]
        self._lib.pk_start(self._state, *arr)
        self.gear = float(cmd0[0]) if np.isfinite(float(cmd0[0])) else 0.0

    def step(self, gear: float, torque_cmd: float, decel_cmd: float, steer_cmd: float):
        """One sample: (actuals (3,), (vx, yaw, ax, ay)), as RealtimeChain.step."""
        c = self._cmd
        c[0], c[1], c[2], c[3] = gear, torque_cmd, decel_cmd, steer_cmd
        self._step(*self._args)
        o = self._out[:]
        self.gear = o[7]
        return (o[0], o[1], o[2]), (o[3], o[4], o[5], o[6])

    def step_row(self, gear: float, torque_cmd: float, decel_cmd: float,
                 steer_cmd: float) -> list[float]:
        """One sample as :meth:`step`, returned as the row (8,) of
        :data:`~parknss.chain.ccode.OUTPUTS` (the Plant step's path: no tuples built)."""
        c = self._cmd
        c[0], c[1], c[2], c[3] = gear, torque_cmd, decel_cmd, steer_cmd
        self._step(*self._args)
        o = self._out[:]
        self.gear = o[7]
        return o

    def run(self, cmds: np.ndarray) -> np.ndarray:
        """Replay commands (T, 4) from the current state; returns (T, 8) rows of
        :data:`~parknss.chain.ccode.OUTPUTS`."""
        c = np.ascontiguousarray(cmds, dtype=np.float64)
        if c.ndim != 2 or c.shape[1] != 4:
            raise ParknssError(f"commands must be (T, 4), got {c.shape}")
        out = np.empty((len(c), len(OUTPUTS)))
        self._lib.pk_run(self._state, c.ctypes.data_as(_DOUBLE_P), len(c),
                         out.ctypes.data_as(_DOUBLE_P))
        if len(c):
            self.gear = float(out[-1, 7])
        return out


def step_many(chains, cmds) -> np.ndarray:
    """One 10 ms sample of each of ``chains`` (NativeChains of one artefact: the same
    compiled library) under ``cmds`` (K, 4) [gear, torque_cmd, decel_cmd, steer_cmd]:
    (K, 8) rows of :data:`~parknss.chain.ccode.OUTPUTS`, in one C call. Each chain's
    state advances exactly as by its own :meth:`NativeChain.step`."""
    chains = list(chains)
    c = np.ascontiguousarray(cmds, dtype=np.float64)
    if c.shape != (len(chains), 4):
        raise ParknssError(f"commands must be ({len(chains)}, 4), got {c.shape}")
    if not chains:
        return np.empty((0, len(OUTPUTS)))
    path = chains[0].path
    if any(ch.path != path for ch in chains):
        raise ParknssError("step_many steps chains of one artefact (one compiled library)")
    lib, k = chains[0]._lib, len(chains)
    out = np.empty((k, len(OUTPUTS)))
    lib.pk_step_many((ctypes.c_void_p * k)(*[ch._addr for ch in chains]), k, c.ctypes.data,
                     out.ctypes.data)
    for ch, g in zip(chains, out[:, 7].tolist(), strict=True):
        ch.gear = g
    return out
