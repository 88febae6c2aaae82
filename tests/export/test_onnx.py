"""The ONNX step: onnx.checker passes, onnxruntime equals the NumPy twin at 1e-5 (float32)
over a whole trial, for the chain and for the NSS alone."""

from __future__ import annotations

import numpy as np
import onnx
import pytest

from parknss.chain import load_chain
from parknss.config import SHIPPED_CHAIN, SHIPPED_NSS, SHIPPED_PLANT
from parknss.export.onnx_step import chain_state, export_onnx, nss_initial_state
from parknss.nss.campaigns import default_campaign
from parknss.outputs import OutputExistsError
from parknss.signals import ACTUAL_CHANNELS, COMMAND_CHANNELS

ort = pytest.importorskip("onnxruntime")


def _session(path):
    so = ort.SessionOptions()
    so.intra_op_num_threads = so.inter_op_num_threads = 1
    return ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])


def _rel(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, float) - b) / np.maximum(1.0, np.abs(b))))


@pytest.mark.parametrize("folder", [None, SHIPPED_CHAIN], ids=["plant", "paper-chain"])
def test_chain_step_equals_the_numpy_twin(tmp_path, folder):
    """The default export (models/plant, monotone brake with its hold) and the paper
    chain (NARX brake)."""
    rep = export_onnx(tmp_path / "chain.onnx", chain_dir=folder)
    onnx.checker.check_model(onnx.load(str(rep.path)), full_check=True)
    sess = _session(rep.path)
    rt = load_chain(folder or SHIPPED_PLANT).rt
    tr = min(default_campaign(), key=lambda t: t.n)  # a whole trial, the shortest
    cm, ac = tr.array(COMMAND_CHANNELS), tr.array(ACTUAL_CHANNELS[1:])
    rt.start([tr["vx"][0], tr["yaw_rate"][0]], ac[0], cm[0])
    worst = 0.0
    for k in range(tr.n):
        s = chain_state(rt)
        nxt, out = sess.run(None, {"state": s.astype(np.float32),
                                   "command": cm[k].astype(np.float32)})
        act, st = rt.step(*cm[k])
        worst = max(worst, _rel(out, np.array([*act, *st, rt.gear])),
                    _rel(nxt, chain_state(rt)))
    assert worst <= 1e-5


def test_nss_step_equals_the_numpy_twin(tmp_path):
    from parknss.chain.realtime import NumpyNSS
    from parknss.nss.checkpoint import load_model

    rep = export_onnx(tmp_path / "nss.onnx", model_dir=SHIPPED_NSS)
    sess = _session(rep.path)
    nss = NumpyNSS(load_model(SHIPPED_NSS).model.double())
    tr = min(default_campaign(), key=lambda t: t.n)
    u = tr.array(ACTUAL_CHANNELS)
    x = nss_initial_state(nss, [tr["vx"][0], tr["yaw_rate"][0]], u[0])
    worst = 0.0
    for k in range(tr.n):
        nxt, out = sess.run(None, {"state": x.astype(np.float32),
                                   "command": u[k].astype(np.float32)})
        us = nss.scale_u(u[k])
        worst = max(worst, _rel(out, np.array(nss.readout(x, us))))
        x = nss.advance(x, us)
        worst = max(worst, _rel(nxt, x))
    assert worst <= 1e-5


def test_refusals(tmp_path):
    from parknss.errors import ParknssError

    (tmp_path / "x.onnx").write_text("")
    with pytest.raises(OutputExistsError):
        export_onnx(tmp_path / "x.onnx")
    with pytest.raises(ParknssError, match="not both"):
        export_onnx(tmp_path / "y.onnx", model_dir=SHIPPED_NSS, chain_dir=SHIPPED_CHAIN)
