"""The generated C step of a chain, compiled by the system C compiler and called through ctypes.

:class:`NativeChain` has the interface of :class:`~parknss.chain.realtime.RealtimeChain`
(``start``, ``step``, ``gear``, ``dt``) and runs the C of :mod:`parknss.chain.ccode`: the
same arithmetic as the NumPy twin (the reference implementation, which stays the default
of :class:`~parknss.chain.deployed.DeployedChain`), equal to it to rounding, several times
faster. :meth:`NativeChain.run` replays a whole command history in one C call.

:func:`compile_library` builds a shared library from C files with ``cc`` (``$CC``, else
gcc, else cc), ``-O3 -std=c99``; the result is cached by the SHA-256 of the sources and
flags under ``$PARKNSS_CACHE`` (default ``~/.cache/parknss``)/native, written atomically,
so a chain compiles once per machine. No compiler, or a failing build, is one-line
:class:`~parknss.errors.ParknssError`.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from parknss.chain.ccode import OUTPUTS, chain_c_source
from parknss.chain.realtime import RealtimeChain
from parknss.errors import ParknssError

CFLAGS: tuple[str, ...] = ("-O3", "-std=c99", "-fPIC", "-shared")
_DOUBLE_P = ctypes.POINTER(ctypes.c_double)


def c_compiler() -> str:
    """The C compiler: ``$CC``, else gcc, else cc; ParknssError when there is none."""
    for cand in (os.environ.get("CC"), "gcc", "cc"):
        if cand and shutil.which(cand):
            return str(shutil.which(cand))
    raise ParknssError("no C compiler found (set CC, or install gcc)")


def cache_dir() -> Path:
    """Where compiled chains are kept: ``$PARKNSS_CACHE/native`` (default ~/.cache/parknss)."""
    root = os.environ.get("PARKNSS_CACHE") or str(Path.home() / ".cache" / "parknss")
    return Path(root) / "native"


def build_shared(files: dict[str, str], out: Path, include: list[Path] | None = None,
                 flags: tuple[str, ...] = CFLAGS) -> Path:
    """Compile the C ``files`` (name -> text, the .c ones compiled) into the shared library
    ``out`` (written atomically); one-line ParknssError on a compiler error."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="parknss-cc-") as tmp:
        src = Path(tmp)
        for name, text in files.items():
            (src / name).write_text(text)
        sources = [str(src / n) for n in sorted(files) if n.endswith(".c")]
        incs = [f"-I{p}" for p in (include or [])]
        lib = src / out.name
        cmd = [c_compiler(), *flags, f"-I{src}", *incs, "-o", str(lib), *sources, "-lm"]
        res = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if res.returncode != 0:
            first = (res.stderr.strip().splitlines() or ["(no message)"])[0]
            raise ParknssError(f"C compilation failed: {first}")
        part = out.with_name(f".{out.name}.{os.getpid()}.part")
        shutil.copyfile(lib, part)
        os.replace(part, out)
    return out


def compile_library(files: dict[str, str]) -> Path:
    """The cached shared library of ``files`` (see the module doc)."""
    h = hashlib.sha256()
    for name in sorted(files):
        h.update(name.encode() + b"\0" + files[name].encode() + b"\0")
    h.update(" ".join(CFLAGS).encode())
    lib = cache_dir() / f"pk_{h.hexdigest()[:24]}.so"
    return lib if lib.is_file() else build_shared(files, lib)


class NativeChain:
    """A chain's generated C step through ctypes (the interface of RealtimeChain)."""

    def __init__(self, rt: RealtimeChain) -> None:
        self.dt = rt.dt
        self.path = compile_library(chain_c_source(rt).files())
        lib = ctypes.CDLL(str(self.path))
        lib.pk_size.restype = ctypes.c_size_t
        for fn in (lib.pk_start, lib.pk_step, lib.pk_run):
            fn.restype = None
        lib.pk_start.argtypes = [ctypes.c_void_p, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P]
        lib.pk_step.argtypes = [ctypes.c_void_p, _DOUBLE_P, _DOUBLE_P]
        lib.pk_run.argtypes = [ctypes.c_void_p, _DOUBLE_P, ctypes.c_long, _DOUBLE_P]
        self._lib = lib
        self._state = ctypes.create_string_buffer(lib.pk_size())
        self._cmd = (ctypes.c_double * 4)()
        self._out = (ctypes.c_double * len(OUTPUTS))()
        self._step = lib.pk_step
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
        self._step(self._state, c, self._out)
        o = self._out[:]
        self.gear = o[7]
        return (o[0], o[1], o[2]), (o[3], o[4], o[5], o[6])

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
