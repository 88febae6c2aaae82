"""The FMU of the shipped chain, built once per test module (gcc: a few seconds)."""

from __future__ import annotations

import pytest
import torch

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def shipped_fmu(tmp_path_factory):
    from parknss.export.fmu import export_fmu

    return export_fmu(tmp_path_factory.mktemp("fmu") / "chain.fmu")
