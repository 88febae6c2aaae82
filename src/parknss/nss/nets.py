"""The one tanh multilayer perceptron, in torch and as its NumPy float64 twin.

Every network of parknss is this shape: ``Linear -> tanh`` per hidden width, then a linear
head (the NSS state net f and output net g, the Hammerstein perceptron ψ, the NARX
perceptron). :func:`tanh_mlp` builds it; :func:`linear_layers` lists its ``nn.Linear``
modules (what the fused kernels and the real-time twins read); :func:`numpy_layers` copies
their weights once into float64 arrays and :func:`numpy_tanh_mlp` evaluates them with the
same arithmetic (``tanh(W @ h + b)``), so a NumPy real-time step equals the torch module to
rounding (tests/nss/test_model.py).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from torch import nn

NumpyLayers = list[tuple[np.ndarray, np.ndarray]]


def tanh_mlp(n_in: int, hidden: Sequence[int], n_out: int = 1) -> nn.Sequential:
    """``Linear(n_in, h0) -> tanh -> ... -> Linear(h_last, n_out)`` (default dtype).

    Modules are created in order, so the initial weights depend only on the torch seed.
    """
    mods: list[nn.Module] = []
    width = n_in
    for h in hidden:
        mods += [nn.Linear(width, h), nn.Tanh()]
        width = h
    mods.append(nn.Linear(width, n_out))
    return nn.Sequential(*mods)


def linear_layers(net: nn.Sequential) -> list[nn.Linear]:
    """The ``nn.Linear`` modules of a :func:`tanh_mlp`, input to head."""
    return [m for m in net if isinstance(m, nn.Linear)]


def numpy_layers(net: nn.Sequential) -> NumpyLayers:
    """(W (out, in), b (out,)) float64 copies of every linear layer, input to head."""
    return [
        (m.weight.detach().double().numpy().copy(), m.bias.detach().double().numpy().copy())
        for m in linear_layers(net)
    ]


def numpy_tanh_mlp(layers: NumpyLayers, z: np.ndarray) -> np.ndarray:
    """The perceptron on one input vector z (in,): tanh hidden layers, linear head (out,)."""
    h = z
    for W, b in layers[:-1]:
        h = np.tanh(W @ h + b)
    W, b = layers[-1]
    return W @ h + b
