"""The native kernels (C loops of the fused rollout and output MLP) against float64 autograd.

Shapes are chosen to run every path of the C product: blocks of 7, 4 and 1 rows, 32- and
16-column blocks and the scalar columns past the last whole vector, output-network chunks
with a remainder, no hidden layer."""

from __future__ import annotations

import pytest
import torch

from helpers.fused import F64, euler_args, euler_reference, mlp_args, mlp_reference
from parknss.errors import ParknssError
from parknss.nss.fused import FusedEulerRollout, euler_forward
from parknss.nss.fused_mlp import FusedTanhMLP

F32 = torch.float32


def _f32(ts):
    return [t.detach().to(F32).requires_grad_(True) for t in ts]


def _rel(a, b) -> float:
    """max |a - b| / max |b| (a float32, b float64)."""
    return float((a.detach().double() - b.detach()).abs().max() / b.detach().abs().max())


@pytest.mark.parametrize(
    ("B", "H", "hidden_layers"),
    [(29, 128, 5), (13, 48, 2), (11, 40, 1), (3, 8, 0), (1, 20, 2)],
)
def test_rollout_and_gradients_agree_with_float64(B, H, hidden_layers):
    """States and every gradient (weights, x0, inputs) to float32 accuracy."""
    x0, U, W0, b0, Wout, bout, hidden = euler_args(B=B, T=40, H=H, hidden_layers=hidden_layers,
                                                   seed=B + H)
    scale = [x0, U, W0 / (2 + 4) ** 0.5 * 2, b0, Wout / H**0.5, bout]
    scale += [h / (H**0.5 if h.dim() == 2 else 1.0) for h in hidden]
    inputs = [t.detach().requires_grad_(True) for t in scale]
    X64 = euler_reference(0.05, *inputs)
    w = torch.linspace(-1.0, 2.0, X64.numel(), dtype=F64).view_as(X64)
    g64 = torch.autograd.grad((X64 * w).sum(), inputs)
    ins32 = _f32(inputs)
    X32 = FusedEulerRollout.apply(0.05, "native", *ins32)
    assert X32.dtype == F32 and torch.equal(X32[0], ins32[0].detach())
    g32 = torch.autograd.grad((X32 * w.to(F32)).sum(), ins32)
    assert _rel(X32, X64) < 2e-6
    for a, b in zip(g32, g64, strict=True):
        assert b.abs().max() > 0
        assert _rel(a, b) < 1e-5


def test_inference_path_equals_training_forward_and_runs_are_bit_identical():
    args = _f32([t for t in (*euler_args(B=9, T=25, H=36, hidden_layers=3, seed=4)[:6],)])
    hidden = _f32(euler_args(B=9, T=25, H=36, hidden_layers=3, seed=4)[6])
    X1 = FusedEulerRollout.apply(0.1, "native", *args, *hidden)
    X2 = FusedEulerRollout.apply(0.1, "native", *args, *hidden)
    g1 = torch.autograd.grad(X1.square().sum(), [*args, *hidden])
    g2 = torch.autograd.grad(X2.square().sum(), [*args, *hidden])
    assert torch.equal(X1, X2) and all(torch.equal(a, b) for a, b in zip(g1, g2, strict=True))
    with torch.no_grad():
        Xi = euler_forward(*args, hidden[0::2], hidden[1::2], dt=0.1, kernels="native")
    assert torch.equal(Xi, X1.detach())


def test_long_rollout_sums_keep_float32_accuracy():
    """2000 steps: the weight gradients summed inside the reverse loop over all steps stay
    about as close to float64 as the reference kernels' float32 (on the same run)."""
    inputs = [t.detach() * 0.5 for t in (*euler_args(B=3, T=2000, H=16, hidden_layers=2,
                                                     seed=9)[:6],)]
    hidden = [t.detach() * 0.5 for t in euler_args(B=3, T=2000, H=16, hidden_layers=2, seed=9)[6]]
    ins64 = [t.requires_grad_(True) for t in (*inputs, *hidden)]
    X64 = FusedEulerRollout.apply(0.01, "reference", *ins64)
    w = torch.cos(torch.arange(X64.numel(), dtype=F64)).view_as(X64)
    g64 = torch.autograd.grad((X64 * w).sum(), ins64)
    errs = {}
    for kernels in ("reference", "native"):
        ins32 = _f32(ins64)
        X32 = FusedEulerRollout.apply(0.01, kernels, *ins32)
        g32 = torch.autograd.grad((X32 * w.to(F32)).sum(), ins32)
        errs[kernels] = max(_rel(a, b) for a, b in zip(g32, g64, strict=True))
    assert errs["native"] < 3 * errs["reference"] + 1e-6, errs


@pytest.mark.parametrize(
    ("N", "H", "layers", "n_out"),
    [(600, 128, 3, 2), (256, 40, 2, 2), (257, 48, 1, 1), (33, 8, 2, 5), (5, 20, 4, 3)],
)
def test_output_mlp_agrees_with_float64(N, H, layers, n_out):
    """y, dL/dx and every weight gradient; N around the chunk of fused_native.CHUNK_ROWS."""
    x, params = mlp_args(N, 5, H, layers, n_out, seed=N, scale=0.5)
    params = [p.detach().requires_grad_(True) for p in params]
    y64 = mlp_reference(x, *params)
    w = torch.linspace(-1.0, 1.3, y64.numel(), dtype=F64).view_as(y64)  # sums that cancel
    g64 = torch.autograd.grad((y64 * w).sum(), [x, *params])
    ins32 = _f32([x, *params])
    y32 = FusedTanhMLP.apply("native", *ins32)
    g32 = torch.autograd.grad((y32 * w.to(F32)).sum(), ins32)
    assert _rel(y32, y64) < 2e-6
    for a, b in zip(g32, g64, strict=True):
        assert _rel(a, b) < 3e-5


def test_tanh_is_accurate_to_two_ulp_over_the_whole_range():
    """The C tanh (polynomial e^x - 1) through a one-unit network: absolute error < 2e-7
    and relative < 2.5e-7 against float64, from 1e-30 to the clamp and beyond (torch's own
    float32 tanh: 3e-8 and 6e-8 on the same points)."""
    a = torch.cat([torch.linspace(-12.0, 12.0, 100_001), torch.logspace(-30, 1, 5000),
                   -torch.logspace(-30, 1, 5000), torch.tensor([0.0, 100.0, -100.0, 1e30])])
    H = 16
    W0, Wo = torch.zeros(H, 1), torch.zeros(1, H)
    W0[0, 0] = Wo[0, 0] = 1.0
    y = FusedTanhMLP.apply("native", a[:, None], W0.requires_grad_(True), torch.zeros(H), Wo,
                           torch.zeros(1)).detach()[:, 0].double()
    ref = torch.tanh(a.double())
    assert float((y - ref).abs().max()) < 2e-7
    nz = ref != 0
    assert float(((y - ref)[nz] / ref[nz]).abs().max()) < 2.5e-7
    assert y[-4] == 0.0 and y[-3] == 1.0 and y[-2] == -1.0 and y[-1] == 1.0


def test_float64_is_refused_in_one_line():
    args = euler_args(B=2, T=5, H=4, hidden_layers=1)
    x0, U, W0, b0, Wout, bout, hidden = args
    with pytest.raises(ParknssError, match="float32 only") as e:
        FusedEulerRollout.apply(0.1, "native", x0, U, W0, b0, Wout, bout, *hidden)
    assert "\n" not in str(e.value)
    x, params = mlp_args(4, 5, 16, 2, 2)
    with pytest.raises(ParknssError, match="float32 only"):
        FusedTanhMLP.apply("native", x, *params)


def test_a_float64_copy_of_a_native_model_runs_the_reference_kernels():
    """A chain holds its NSS in float64: a model configured for the float32-only native
    kernels then runs the reference ones, the same numbers as a reference model's."""
    from helpers.synth import make_campaign, tiny_model
    from parknss.data.windows import whole_trials

    camp = make_campaign(120, reps=1)
    nat, _ = tiny_model(camp, seed=3, dtype="float32", model={"fused_kernels": "native"})
    ref, _ = tiny_model(camp, seed=3, dtype="float32")
    w = whole_trials(list(camp))
    x0, u = torch.as_tensor(w.states[:, 0]), torch.as_tensor(w.inputs)
    assert nat.kernels() == "native" and ref.kernels() == "reference"
    nat, ref = nat.double(), ref.double()
    assert nat.kernels() == "reference"
    with torch.no_grad():
        a, b = nat.rollout(x0, u), ref.rollout(x0, u)
    assert torch.equal(a.state_s, b.state_s) and torch.equal(a.ax, b.ax)


def test_native_training_in_float64_is_refused_by_the_config():
    from parknss.errors import ConfigError
    from parknss.nss.config import NSSConfig, with_overrides

    with pytest.raises(ConfigError, match="float32 only"):
        with_overrides(NSSConfig(), model={"fused_kernels": "native"}, train={"dtype": "float64"})


def test_no_compiler_is_one_line_naming_the_way_out(monkeypatch, tmp_path):
    from helpers.cbuild import no_c_compiler
    from parknss.nss import fused_native

    with no_c_compiler(monkeypatch, tmp_path, fused_native.library):
        with pytest.raises(ParknssError, match=r"no C compiler.*fused_kernels=reference") as e:
            fused_native.library()
        assert "\n" not in str(e.value)
