"""Learned-memory candidates: NARX perceptrons (50 ms and 1 s windows), GRU, LSTM.

* NARX (``narx``: the command and its 5 lagged samples, 50 ms; ``narx1s``: a 1 s window,
  100 lags): ỹ[k] = MLP([c̃[k-n..k], f̃[k]]) + a linear bypass on the same inputs. The
  window before the first sample is the first command repeated (the ring buffer's fill).
* GRU (16-d state) and LSTM (16-d, long-memory brake): h[k] = cell(h[k-1], [c̃[k], f̃[k]]),
  ỹ[k] = head(h[k]), h[-1] = 0. ``step`` evaluates the very equations of torch.nn.GRU /
  LSTM (gate order r, z, n and i, f, g, o) so rollout and step agree to rounding.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor, nn

from parknss.actuators.models import ActuatorModel
from parknss.actuators.steppers import GRUStepper, LSTMStepper, NARXStepper
from parknss.nss.nets import tanh_mlp


class NARX(ActuatorModel):
    """Static perceptron on a sliding command window (see the module doc)."""

    stepper_cls = NARXStepper

    def __init__(self, spec, scaling, cfg) -> None:
        super().__init__(spec, scaling, cfg)
        self.lags = cfg.narx_long_lags if spec.arch == "narx1s" else cfg.narx_lags
        n_in = self.lags + 1 + self.n_feat
        self.net = tanh_mlp(n_in, tuple(cfg.narx_hidden)).double()
        self.skip = nn.Linear(n_in, 1).double()
        with torch.no_grad():
            self.net[-1].weight.mul_(0.1)
            self.net[-1].bias.zero_()
            self.skip.weight.zero_()
            self.skip.bias.zero_()

    def init_affine(self, k: float, b: float, w: np.ndarray) -> None:
        with torch.no_grad():
            self.skip.weight[0, self.lags] = float(k)  # the newest command sample
            self.skip.weight[0, self.lags + 1 :] = torch.as_tensor(np.asarray(w, float))
            self.skip.bias.fill_(float(b))

    def head(self, z: Tensor) -> Tensor:
        return (self.net(z) + self.skip(z))[..., 0]

    def rollout(self, cmd, feat, y0):
        c = self.sc_cmd(cmd)
        pad = c[:, :1].expand(-1, self.lags)
        win = torch.cat([pad, c], dim=1).unfold(1, self.lags + 1, 1)  # (B, T, n+1)
        z = torch.cat([win, self.features_or_empty(feat, c.shape)], dim=-1)
        return self.unsc_y(self.head(z))

    def init_state(self, cmd0, y0):
        c0 = self.sc_cmd(cmd0.to(self.c_off.dtype))
        return (c0[:, None].expand(-1, self.lags).clone(),)

    def step(self, state, cmd, feat):
        (hist,) = state
        c = self.sc_cmd(cmd)
        win = torch.cat([hist, c[:, None]], dim=1)
        z = torch.cat([win, self.features_or_empty(feat, c.shape)], dim=-1)
        return self.unsc_y(self.head(z)), (win[:, 1:],)


class _Recurrent(ActuatorModel):
    """Shared parts of the GRU and LSTM candidates."""

    cell_cls: type[nn.RNNBase]

    def __init__(self, spec, scaling, cfg, hidden: int) -> None:
        super().__init__(spec, scaling, cfg)
        self.hidden = hidden
        self.rnn = self.cell_cls(1 + self.n_feat, hidden, batch_first=True).double()
        self.out = nn.Linear(hidden, 1).double()

    def init_affine(self, k: float, b: float, w: np.ndarray) -> None:
        with torch.no_grad():
            self.out.bias.fill_(float(b))

    def inputs(self, cmd: Tensor, feat: Tensor | None) -> Tensor:
        c = self.sc_cmd(cmd)
        return torch.cat([c[..., None], self.features_or_empty(feat, c.shape)], dim=-1)

    def rollout(self, cmd, feat, y0):
        h, _ = self.rnn(self.inputs(cmd, feat))
        return self.unsc_y(self.out(h)[..., 0])

    def _gates(self, x: Tensor, h: Tensor) -> tuple[Tensor, Tensor]:
        r = self.rnn
        return (
            x @ r.weight_ih_l0.T + r.bias_ih_l0,
            h @ r.weight_hh_l0.T + r.bias_hh_l0,
        )


class GRUModel(_Recurrent):
    """GRU with a 16-d hidden state and a linear readout."""

    cell_cls = nn.GRU
    stepper_cls = GRUStepper

    def __init__(self, spec, scaling, cfg) -> None:
        super().__init__(spec, scaling, cfg, cfg.gru_hidden)

    def init_state(self, cmd0, y0):
        return (torch.zeros(cmd0.shape[0], self.hidden, dtype=self.c_off.dtype),)

    def step(self, state, cmd, feat):
        (h,) = state
        gi, gh = self._gates(self.inputs(cmd, feat), h)
        H = self.hidden
        r = torch.sigmoid(gi[:, :H] + gh[:, :H])
        z = torch.sigmoid(gi[:, H : 2 * H] + gh[:, H : 2 * H])
        n = torch.tanh(gi[:, 2 * H :] + r * gh[:, 2 * H :])
        h1 = (1.0 - z) * n + z * h
        return self.unsc_y(self.out(h1)[:, 0]), (h1,)


class LSTMModel(_Recurrent):
    """LSTM with a 16-d hidden state and a linear readout (long-memory brake)."""

    cell_cls = nn.LSTM
    stepper_cls = LSTMStepper

    def __init__(self, spec, scaling, cfg) -> None:
        super().__init__(spec, scaling, cfg, cfg.lstm_hidden)

    def init_state(self, cmd0, y0):
        z = torch.zeros(cmd0.shape[0], self.hidden, dtype=self.c_off.dtype)
        return (z, z.clone())

    def step(self, state, cmd, feat):
        h, c = state
        gi, gh = self._gates(self.inputs(cmd, feat), h)
        g = gi + gh
        H = self.hidden
        i = torch.sigmoid(g[:, :H])
        f = torch.sigmoid(g[:, H : 2 * H])
        gg = torch.tanh(g[:, 2 * H : 3 * H])
        o = torch.sigmoid(g[:, 3 * H :])
        c1 = f * c + i * gg
        h1 = o * torch.tanh(c1)
        return self.unsc_y(self.out(h1)[:, 0]), (h1, c1)
