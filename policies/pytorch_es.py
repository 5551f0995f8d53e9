"""pytorch-es's two networks (atgambardella/pytorch-es ``model.py``; docs/original.md, "pytorch-es"), as static
policies.

Both use selu (Klambauer et al. 2017: scale 1.0507..., alpha 1.6732...), which pytorch-es chose
instead of virtual batch norm, and biases everywhere; their weights are evolved directly, like the
default static network, and saved the same way (one flat ``.dat`` vector, the original ES names).

- ``SmallNetPolicy`` (``--network small``, pytorch-es's ``--small-net``): for state vectors,
  Linear(obs, 64) -> selu -> Linear(64, 64) -> selu -> Linear(64, actions). 4 610 parameters on
  CartPole. One compiled call per step.
- ``ConvLSTMPolicy`` (``--network lstm``, pytorch-es's default): for images (pytorch-es's 1 x 42 x 42
  frames, ``envs.pytorch_es``), four Conv2d(., 32, 3, stride 2, padding 1) + selu (42 -> 21 -> 11 ->
  6 -> 3), flattened to 288, LSTMCell(288, 256), Linear(256, actions): 588 710 parameters on Pong.
  Its hidden and cell state are the policy state: zeros at every ``reset``, carried by ``act``, so
  the rollout does not know the network is recurrent. Compiled kernels (im2col and products for the
  convs, one pass over [W_ih | W_hh] for the gates), single-threaded, on preallocated buffers: a few
  times faster than torch's eager conv2d and lstm_cell on these small sizes.

Every sum runs in the order PyTorch's formulas write it (the bias, then the inputs in order), with no
fastmath, and vectorises across a layer's outputs (the weights are transposed once per episode), never
inside one sum; exp, tanh and the sigmoid are ``policies.elementary``'s. So the numbers are the same on
every machine (docs/reproducibility.md), within a few float32 ulps of torch's.

The flat vector is the networks' ``state_dict`` order (each tensor C-order), as pytorch-es's
``es_params`` listed them, and each part starts at PyTorch's default initialisation, as pytorch-es
left it (its ``weights_init`` was never called). pytorch-es picked the argmax of the softmax of the
output, which is the argmax of the output: the environments' ``ArgmaxAction``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from policies.elementary import exp32, rational_tanh, sigmoid32
from policies.init import default_init
from policies.network import Layout, NetworkSpec
from policies.plugin import Network
from policies.static import WeightFile

SELU_ALPHA = np.float32(1.6732632423543772848170429916717)
SELU_SCALE = np.float32(1.0507009873554804934193349852946)
SMALL_HIDDEN = 64
CONV_CHANNELS = 32
CONV_LAYERS = 4
LSTM_HIDDEN = 256


# --- the small net -------------------------------------------------------------------------------


_FLAGS = dict(cache=True, nogil=True, error_model="numpy")  # no fastmath: the sums in the order written


@njit(inline="always")
def _selu(x: np.float32) -> np.float32:
    """selu(x) = scale * x for x > 0, scale * alpha * (exp(x) - 1) otherwise."""
    negative = SELU_SCALE * SELU_ALPHA * (exp32(min(x, np.float32(0.0))) - np.float32(1.0))
    return SELU_SCALE * x if x > 0 else negative


@njit(**_FLAGS)
def _selu_layer(weights_t, bias, pre, post, selu):
    """post = selu(W @ pre + b) (or without selu), ``weights_t`` = W^T (in, out): post[j] = b[j] + W[j, 0] pre[0]
    + W[j, 1] pre[1] + ..., summed in that order, the outputs side by side."""
    post[:] = bias
    for i in range(weights_t.shape[0]):
        activity, row = pre[i], weights_t[i]
        for j in range(post.shape[0]):
            post[j] += row[j] * activity
    if selu:
        for j in range(post.shape[0]):
            post[j] = _selu(post[j])


@njit(**_FLAGS)
def small_forward(w1, b1, w2, b2, w3, b3, obs, h1, h2, out, squash_out):
    """The small net, its weights transposed (in, out)."""
    x = obs.astype(np.float32)
    _selu_layer(w1, b1, x, h1, True)
    _selu_layer(w2, b2, h1, h2, True)
    _selu_layer(w3, b3, h2, out, False)
    if squash_out:
        for j in range(out.shape[0]):
            out[j] = rational_tanh(out[j])


@dataclass
class SmallNetState:
    layers: tuple[np.ndarray, ...]  # w1, b1, w2, b2, w3, b3: the weights transposed (in, out), the biases views
    h1: np.ndarray
    h2: np.ndarray
    out: np.ndarray


class SmallNetPolicy(WeightFile):
    def __init__(self, net: NetworkSpec):
        if net.pixels:
            raise ValueError(f"--network small is pytorch-es's MLP for state vectors, but this environment's "
                             f"observations are images {net.obs_shape}; use --network default or lstm")
        self.net = net
        n_obs, n_actions = net.obs_shape[0], net.n_actions
        self.layout = Layout([("linear1.weight", (SMALL_HIDDEN, n_obs)), ("linear1.bias", (SMALL_HIDDEN,)),
                              ("linear2.weight", (SMALL_HIDDEN, SMALL_HIDDEN)), ("linear2.bias", (SMALL_HIDDEN,)),
                              ("actor_linear.weight", (n_actions, SMALL_HIDDEN)), ("actor_linear.bias", (n_actions,))])
        self.num_params = self.layout.size
        self.penalised = slice(0, self.num_params)
        self._fan_in = {name: (n_obs if name.startswith("linear1") else SMALL_HIDDEN) for name in self.layout.parts}

    def initial_params(self, rng: np.random.Generator) -> np.ndarray:
        return default_init(self.layout, rng, self._fan_in)

    def reset(self, params: np.ndarray, rng: np.random.Generator | None = None) -> SmallNetState:
        params = np.ascontiguousarray(params, dtype=np.float32)
        layers = tuple(np.ascontiguousarray(self.layout.view(params, name).T) for name in self.layout.parts)
        return SmallNetState(layers, np.empty(SMALL_HIDDEN, np.float32), np.empty(SMALL_HIDDEN, np.float32),
                             np.empty(self.net.n_actions, np.float32))

    def act(self, params: np.ndarray, state: SmallNetState, obs: np.ndarray):
        small_forward(*state.layers, np.asarray(obs), state.h1, state.h2, state.out, self.net.squash_out)
        return state.out, state


# --- the conv-LSTM -------------------------------------------------------------------------------


@njit(cache=True)
def conv_output(size: int) -> int:
    """One Conv2d(k 3, stride 2, padding 1) on ``size`` pixels."""
    return (size + 2 - 3) // 2 + 1


@njit(**_FLAGS)
def conv_layer(image, padded, weights, bias, patches, out):
    """Conv2d(k 3, stride 2, padding 1) + selu of a flat (channels, height, width) image, as im2col and a product.

    ``padded`` (channels, height + 2, width + 2) has a zero border and gets the image inside it;
    ``patches`` each output position's input patch, as (channels * 9, positions); ``out`` (32, positions)
    the result. Each output is its bias plus the patch's products in order; the product's inner loop runs
    along the positions: long, contiguous, and across independent outputs.
    """
    channels, padded_height, padded_width = padded.shape
    height, width = padded_height - 2, padded_width - 2
    padded[:, 1:height + 1, 1:width + 1] = image.reshape(channels, height, width)
    out_width, positions = conv_output(width), out.shape[1]
    for position in range(positions):
        top, left = 2 * (position // out_width), 2 * (position % out_width)
        for channel in range(channels):
            for ki in range(3):
                for kj in range(3):
                    patches[(channel * 3 + ki) * 3 + kj, position] = padded[channel, top + ki, left + kj]
    for filter_ in range(out.shape[0]):
        row = out[filter_]
        row[:] = bias[filter_]
        for k in range(patches.shape[0]):
            weight, patch = weights[filter_, k], patches[k]
            for position in range(positions):
                row[position] += weight * patch[position]
        for position in range(positions):
            row[position] = _selu(row[position])


@njit(**_FLAGS)
def lstm_step(lstm_weights_t, lstm_bias, inputs, cell, gates, actor_weights, actor_bias, out, squash_out):
    """The LSTM cell (PyTorch's gate order i, f, g, o; ``inputs`` = [features | hidden], ``lstm_weights_t`` =
    [W_ih | W_hh]^T (inputs, gates), ``lstm_bias`` = b_ih + b_hh), its new hidden state written into
    ``inputs``, then the head. Each gate is its bias plus the inputs' products in order, the gates side by side."""
    hidden = cell.shape[0]
    n_features = inputs.shape[0] - hidden
    gates[:] = lstm_bias
    for k in range(inputs.shape[0]):
        activity, row = inputs[k], lstm_weights_t[k]
        for gate in range(gates.shape[0]):
            gates[gate] += row[gate] * activity
    for unit in range(hidden):
        cell[unit] = (sigmoid32(gates[hidden + unit]) * cell[unit]
                      + sigmoid32(gates[unit]) * rational_tanh(gates[2 * hidden + unit]))
        inputs[n_features + unit] = sigmoid32(gates[3 * hidden + unit]) * rational_tanh(cell[unit])
    for action in range(out.shape[0]):
        total, row = actor_bias[action], actor_weights[action]
        for unit in range(hidden):
            total += row[unit] * inputs[n_features + unit]
        out[action] = rational_tanh(total) if squash_out else total


@dataclass
class LSTMState:
    conv_weights: tuple[np.ndarray, ...]  # (32, channels * 9) each: views of the parameters
    conv_biases: tuple[np.ndarray, ...]
    lstm_weights: np.ndarray  # (features + 256, 1024): [W_ih | W_hh]^T
    lstm_bias: np.ndarray  # b_ih + b_hh
    actor: tuple[np.ndarray, np.ndarray]
    padded: tuple[np.ndarray, ...]  # work buffers of the conv layers: zero-bordered inputs,
    columns: tuple[np.ndarray, ...]  # patches (see conv_layer),
    features: tuple[np.ndarray, ...]  # outputs
    inputs: np.ndarray  # [conv features | hidden state]: the hidden state is inputs[features:]
    cell: np.ndarray
    gates: np.ndarray
    out: np.ndarray


class ConvLSTMPolicy(WeightFile):
    def __init__(self, net: NetworkSpec):
        if not net.pixels:
            raise ValueError(f"--network lstm is pytorch-es's conv-LSTM for images, but this environment's "
                             f"observations are vectors {net.obs_shape}; use --network default or small")
        self.net = net
        channels, height, width = net.obs_shape
        self.shapes = []
        parts, self._fan_in = [], {}
        for index in range(1, CONV_LAYERS + 1):
            self.shapes.append((channels, height, width))
            parts += [(f"conv{index}.weight", (CONV_CHANNELS, channels, 3, 3)), (f"conv{index}.bias", (CONV_CHANNELS,))]
            self._fan_in.update({f"conv{index}.weight": channels * 9, f"conv{index}.bias": channels * 9})
            channels, height, width = CONV_CHANNELS, conv_output(height), conv_output(width)
        self.features = channels * height * width  # 288 for 42 x 42
        gates = 4 * LSTM_HIDDEN
        parts += [("lstm.weight_ih", (gates, self.features)), ("lstm.weight_hh", (gates, LSTM_HIDDEN)),
                  ("lstm.bias_ih", (gates,)), ("lstm.bias_hh", (gates,)),
                  ("actor_linear.weight", (net.n_actions, LSTM_HIDDEN)), ("actor_linear.bias", (net.n_actions,))]
        self._fan_in.update({name: LSTM_HIDDEN for name, _ in parts[2 * CONV_LAYERS:]})
        self.layout = Layout(parts)
        self.num_params = self.layout.size
        self.penalised = slice(0, self.num_params)

    def initial_params(self, rng: np.random.Generator) -> np.ndarray:
        return default_init(self.layout, rng, self._fan_in)

    def reset(self, params: np.ndarray, rng: np.random.Generator | None = None) -> LSTMState:
        """The episode's weights in the kernel's shapes, zero hidden and cell states, work buffers."""
        params = np.ascontiguousarray(params, dtype=np.float32)
        view = self.layout.view
        conv_weights = tuple(view(params, f"conv{index}.weight").reshape(CONV_CHANNELS, -1)
                             for index in range(1, CONV_LAYERS + 1))
        conv_biases = tuple(view(params, f"conv{index}.bias") for index in range(1, CONV_LAYERS + 1))
        lstm_weights = np.ascontiguousarray(
            np.concatenate([view(params, "lstm.weight_ih"), view(params, "lstm.weight_hh")], axis=1).T)
        lstm_bias = view(params, "lstm.bias_ih") + view(params, "lstm.bias_hh")
        positions = [conv_output(height) * conv_output(width) for _, height, width in self.shapes]
        columns = tuple(np.zeros((channels * 9, size), np.float32)
                        for (channels, _, _), size in zip(self.shapes, positions))
        features = tuple(np.zeros((CONV_CHANNELS, size), np.float32) for size in positions)
        padded = tuple(np.zeros((channels, height + 2, width + 2), np.float32)
                       for channels, height, width in self.shapes)
        return LSTMState(conv_weights, conv_biases, lstm_weights, lstm_bias,
                         (view(params, "actor_linear.weight"), view(params, "actor_linear.bias")), padded, columns,
                         features,
                         np.zeros(self.features + LSTM_HIDDEN, np.float32), np.zeros(LSTM_HIDDEN, np.float32),
                         np.zeros(4 * LSTM_HIDDEN, np.float32), np.zeros(self.net.n_actions, np.float32))

    def act(self, params: np.ndarray, state: LSTMState, obs: np.ndarray):
        image = np.ascontiguousarray(obs, dtype=np.float32).reshape(-1)
        for layer in range(CONV_LAYERS):
            conv_layer(image, state.padded[layer], state.conv_weights[layer], state.conv_biases[layer],
                       state.columns[layer], state.features[layer])
            image = state.features[layer].reshape(-1)
        state.inputs[:self.features] = image
        lstm_step(state.lstm_weights, state.lstm_bias, state.inputs, state.cell, state.gates, *state.actor, state.out,
                  self.net.squash_out)
        return state.out, state


SMALL = Network("small", about="pytorch-es's 64-64 selu MLP (state vectors)", build=SmallNetPolicy)
LSTM = Network("lstm", about="pytorch-es's conv-LSTM on its 42x42 normalised frames (images)", build=ConvLSTMPolicy,
               preprocessing="pytorch-es")
