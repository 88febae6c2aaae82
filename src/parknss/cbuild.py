"""C sources compiled by the system C compiler into a cached shared library (for ctypes).

:func:`compile_library` builds a shared library from C files with ``cc`` (``$CC``, else
gcc, else cc), by default ``-O3 -std=c99 -march=native`` (:data:`NATIVE_FLAGS`: this
machine's vector instructions; a compiler that refuses the flags gets the portable build,
:data:`CFLAGS`); the result is cached by the SHA-256 of the sources, the flags and the
machine's CPU under ``$PARKNSS_CACHE`` (default ``~/.cache/parknss``)/native, written
atomically, so a library compiles once per machine. No compiler, or a failing build, is
one-line :class:`~parknss.errors.ParknssError`. Users: the chain's generated C step
(:mod:`parknss.chain.native`), the FMU (:mod:`parknss.export.fmu`), the native kernels
of the fused NSS rollout (:mod:`parknss.nss.fused_native`) and the ISO rating's DTW
(:mod:`parknss.metrics.dtw_native`).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

from parknss.errors import ParknssError

CFLAGS: tuple[str, ...] = ("-O3", "-std=c99", "-fPIC", "-shared")
NATIVE_FLAGS: tuple[str, ...] = (*CFLAGS, "-march=native")


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


def _machine() -> bytes:
    """What a ``-march=native`` build depends on: the architecture and the CPU's flags."""
    flags = ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith(("flags", "Features")):
                flags = line
                break
    return f"{platform.machine()} {platform.processor()} {flags}".encode()


def compile_library(files: dict[str, str], flags: tuple[str, ...] = NATIVE_FLAGS) -> Path:
    """The cached shared library of ``files`` (see the module doc)."""
    h = hashlib.sha256()
    for name in sorted(files):
        h.update(name.encode() + b"\0" + files[name].encode() + b"\0")
    h.update(" ".join(flags).encode())
    if "-march=native" in flags:
        h.update(_machine())
    lib = cache_dir() / f"pk_{h.hexdigest()[:24]}.so"
    if lib.is_file():
        return lib
    try:
        return build_shared(files, lib, flags=flags)
    except ParknssError:
        if flags == CFLAGS:
            raise
        return compile_library(files, CFLAGS)
