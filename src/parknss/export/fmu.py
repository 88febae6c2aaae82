"""``parknss export fmu``: the chain as an FMI 2.0 co-simulation FMU.

:func:`export_fmu` loads a chain artefact, generates its C step
(:func:`parknss.chain.ccode.chain_c_source`) and the FMI wrapper
(:mod:`parknss.export.fmi2_source`), compiles them with the system C compiler against
FMPy's FMI 2.0 headers into ``binaries/linux64/parknss_chain.so`` and zips::

    modelDescription.xml        inputs, outputs, parameters (value references, FMI units,
                                Integer gears), DefaultExperiment step 0.01 s and the
                                stop time of the config, the generation date (UTC; from
                                SOURCE_DATE_EPOCH when set, for reproducible builds)
    sources/                    pk_chain.h, pk_chain.c, fmi2_chain.c, buildDescription.xml
    binaries/linux64/           the shared library
    resources/chain.json        the artefact's chain.json (provenance)

The FMU is written atomically; an existing file is refused unless ``overwrite``.
"""

from __future__ import annotations

import hashlib
import os
import platform
import tempfile
import time
import uuid
import zipfile
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from parknss import __version__
from parknss.cbuild import build_shared
from parknss.chain.ccode import chain_c_source
from parknss.chain.deployed import DeployedChain, load_chain
from parknss.config import SHIPPED_PLANT
from parknss.errors import ParknssError
from parknss.export.config import FmuConfig, load_export_config
from parknss.export.fmi2_source import (
    INPUTS,
    OUTPUTS,
    UNITS,
    VARIABLES,
    Domain,
    Var,
    wrapper_source,
)
from parknss.outputs import atomic_file, check_file_target

MODEL_ID = "parknss_chain"
WRAPPER = "fmi2_chain.c"


@dataclass(frozen=True)
class FmuReport:
    """What was written: the FMU path, its GUID, the size in bytes, the build time (s)."""

    path: Path
    guid: str
    bytes: int
    build_s: float

    def to_json(self) -> dict:
        return {"fmu": str(self.path), "guid": self.guid, "bytes": self.bytes,
                "build_s": round(self.build_s, 3)}


def fmi_headers() -> Path:
    """FMPy's FMI headers (``fmpy/c-code``); one-line ParknssError when absent."""
    try:
        import fmpy
    except ImportError as exc:
        raise ParknssError("FMPy is not installed (it ships the FMI 2.0 headers)") from exc
    d = Path(fmpy.__file__).parent / "c-code"
    if not (d / "fmi2Functions.h").is_file():
        raise ParknssError(f"{d}: FMPy's FMI 2.0 headers not found")
    return d


def _platform() -> str:
    if platform.system() != "Linux" or platform.machine() not in ("x86_64", "AMD64"):
        raise ParknssError(f"FMU binaries are built for linux64 only, not "
                           f"{platform.system()} {platform.machine()}")
    return "linux64"


def _variable(v: Var) -> str:
    """One ScalarVariable element: Reals continuous (parameters fixed) with their unit,
    Integers discrete."""
    cont = "discrete" if v.type == "Integer" else "continuous"
    if v.causality == "output":
        attrs, start = f'variability="{cont}" initial="calculated"', ""
    elif v.causality == "input":
        attrs, start = f'variability="{cont}"', f' start="{v.start!r}"'
    else:
        attrs, start = 'variability="fixed" initial="exact"', f' start="{v.start!r}"'
    unit = f' unit="{v.unit}"' if v.unit else ""
    return (f'    <ScalarVariable name="{v.name}" valueReference="{v.vr}" '
            f'causality="{v.causality}" {attrs} description={quoteattr(v.description)}>'
            f'<{v.type}{unit}{start}/></ScalarVariable>')


def _unit_definitions() -> str:
    rows = []
    for name, (base, factor) in UNITS.items():
        exps = " ".join(f'{k}="{e}"' for k, e in base.items())
        fac = f' factor="{factor!r}"' if factor != 1.0 else ""
        rows.append(f'    <Unit name="{name}"><BaseUnit {exps}{fac}/></Unit>')
    return "\n".join(rows)


def generation_time() -> str:
    """UTC now as ISO 8601, or ``SOURCE_DATE_EPOCH`` (reproducible builds) when set."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    try:
        when = (datetime.fromtimestamp(int(epoch), tz=UTC) if epoch
                else datetime.now(tz=UTC))
    except (ValueError, OverflowError, OSError) as exc:
        raise ParknssError(f"SOURCE_DATE_EPOCH={epoch!r}: not a Unix time ({exc})") from None
    return when.strftime("%Y-%m-%dT%H:%M:%SZ")


def model_description(guid: str, description: str, cfg: FmuConfig | None = None) -> str:
    """modelDescription.xml of the chain FMU."""
    cfg = cfg or load_export_config().fmu
    rows, index = [], {}
    for i, v in enumerate(VARIABLES, start=1):
        index[v.vr] = i
        rows.append(_variable(v))
    outs = "\n".join(f'      <Unknown index="{index[v.vr]}"/>' for v in OUTPUTS)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{MODEL_ID}" guid="{guid}"
  description={quoteattr(description)} generationTool="parknss {__version__}"
  generationDateAndTime="{generation_time()}"
  variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{MODEL_ID}" canHandleVariableCommunicationStepSize="true"
    canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="true"/>
  <UnitDefinitions>
{_unit_definitions()}
  </UnitDefinitions>
  <LogCategories>
    <Category name="error" description="errors of the FMI calls"/>
    <Category name="domain" description="inputs or states outside the identified domain"/>
  </LogCategories>
  <DefaultExperiment startTime="0" stopTime="{cfg.stop_time_s!r}" stepSize="0.01"/>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
{outs}
    </Outputs>
    <InitialUnknowns>
{outs}
    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


_BUILD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiBuildDescription fmiVersion="3.0">
  <BuildConfiguration modelIdentifier="{mid}">
    <SourceFileSet language="C99">
      <SourceFile name="pk_chain.c"/>
      <SourceFile name="{wrapper}"/>
    </SourceFileSet>
  </BuildConfiguration>
</fmiBuildDescription>
"""


def identified_domain(dep: DeployedChain, cfg: FmuConfig) -> Domain:
    """The domain the FMU checks: the envelope's command domain, and the NSS's clip range
    of vx and yaw rate (the 0.5th-99.5th percentiles of its training data) widened by
    ``cfg.domain_margin`` of the span on each side."""
    env, nss = dep.rt.env.env, dep.rt.nss
    lo, hi = np.asarray(nss.st_lo, float)[:2], np.asarray(nss.st_hi, float)[:2]
    pad = cfg.domain_margin * (hi - lo)
    return Domain(tuple(env.cmd_lo), tuple(env.cmd_hi), tuple((lo - pad).tolist()),
                  tuple((hi + pad).tolist()))


def export_fmu(out: str | Path, chain_dir: str | Path | None = None,
               overwrite: bool = False) -> FmuReport:
    """Write the FMU of the chain at ``chain_dir`` (default: the shipped chain) to ``out``."""
    t0 = time.perf_counter()
    out = Path(out)
    if out.suffix != ".fmu":
        raise ParknssError(f"{out}: an FMU file name ends in .fmu")
    out = check_file_target(out, overwrite=overwrite)  # before any work
    plat = _platform()
    src_dir = Path(chain_dir) if chain_dir is not None else SHIPPED_PLANT
    dep = load_chain(src_dir)
    csrc = chain_c_source(dep.rt, name=f"parknss chain {src_dir.name}")
    guid = "{" + str(uuid.UUID(hashlib.sha256(csrc.source.encode()).hexdigest()[:32])) + "}"
    cfg = load_export_config().fmu
    files = {**csrc.files(), WRAPPER: wrapper_source(guid, identified_domain(dep, cfg))}
    with tempfile.TemporaryDirectory(prefix="parknss-fmu-") as tmp:
        lib = build_shared(files, Path(tmp) / f"{MODEL_ID}.so", include=[fmi_headers()])
        lib_bytes = lib.read_bytes()
    md = model_description(guid, f"parknss command-to-vehicle chain ({src_dir.name}): "
                           f"{', '.join(v.name for v in INPUTS)} -> vehicle, 10 ms", cfg)
    with atomic_file(out) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("modelDescription.xml", md)
        for name, text in files.items():
            zf.writestr(f"sources/{name}", text)
        zf.writestr("sources/buildDescription.xml", _BUILD.format(mid=MODEL_ID, wrapper=WRAPPER))
        zf.writestr(f"binaries/{plat}/{MODEL_ID}.so", lib_bytes)
        zf.write(src_dir / "chain.json", "resources/chain.json")
    return FmuReport(out, guid, out.stat().st_size, time.perf_counter() - t0)
