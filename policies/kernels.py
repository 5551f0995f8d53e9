"""Compiled per-step kernels: the dense three-layer head, static and Hebbian.

Every network of the project ends in the same head, in -> 128 -> 64 -> out without biases
(Najarro & Risi 2020, §3.1 of the upstream spec). One call per environment step runs the whole
head, so the interpreter is crossed once per step instead of a dozen times:

- ``static_forward`` reads the weights straight out of the flat parameter vector.
- ``hebbian_forward_update`` runs each layer's forward pass and then, while the row is still in
  cache, applies the plastic update to that row.

The Hebbian update is evaluated in a folded form. Every rule of the paper is an instance of
    dw_ij = eta * (A o_i o_j + B o_i + C o_j + D_in) + D_out
which, per synapse, is  (a o_j + b) o_i + c o_j + d  with a = eta A, b = eta B, c = eta C and
d = eta D_in + D_out (see ``policies.rules``). The folding happens once per episode, so the kernel
reads four coefficients per synapse whatever the rule.

Weight normalisation (each layer divided by its largest |w| after every update, spec §4.3) is
kept lazy: a layer's stored weights times ``scale[layer]`` are the true weights. The division is
therefore folded into the next step's single pass over the layer instead of costing a pass of its
own. A layer whose weights are all zero is left as it is instead of turning into NaN.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_FLAGS = dict(fastmath=True, cache=True, nogil=True)


@njit(**_FLAGS)
def _tanh(x):
    # exp-based tanh in float64: as exact as libm's tanhf at float32 precision, and about three
    # times faster here than numba's scalar tanh.
    e = math.exp(-2.0 * abs(x))
    y = (1.0 - e) / (1.0 + e)
    return np.float32(y if x >= 0 else -y)


@njit(**_FLAGS)
def _load_input(obs, x):
    for i in range(x.shape[0]):
        x[i] = np.float32(obs[i])


@njit(**_FLAGS)
def _dense(w, offset, n_out, n_in, pre, post, scale, squash):
    """post = act(scale * W @ pre) with W (n_out, n_in) stored C-order at w[offset:]."""
    for j in range(n_out):
        row = offset + j * n_in
        total = np.float32(0.0)
        for i in range(n_in):
            total += w[row + i] * pre[i]
        total *= scale
        post[j] = _tanh(total) if squash else total


@njit(**_FLAGS)
def static_forward(params, obs, work, n_in, n_h1, n_h2, n_out, squash_out):
    """The static head on ``params`` = [W1 (n_h1, n_in), W2 (n_h2, n_h1), W3 (n_out, n_h2)].

    ``work`` holds [x | h1 | h2 | out]; the output is its last ``n_out`` values.
    """
    one = np.float32(1.0)
    x = work[:n_in]
    h1 = work[n_in:n_in + n_h1]
    h2 = work[n_in + n_h1:n_in + n_h1 + n_h2]
    out = work[n_in + n_h1 + n_h2:]
    _load_input(obs, x)
    _dense(params, 0, n_h1, n_in, x, h1, one, True)
    _dense(params, n_h1 * n_in, n_h2, n_h1, h1, h2, one, True)
    _dense(params, n_h1 * n_in + n_h2 * n_h1, n_out, n_h2, h2, out, one, squash_out)


@njit(**_FLAGS)
def _plastic_layer(w, k, offset, n_out, n_in, pre, post, scale, squash):
    """Forward one layer with the current weights, then update it in place; returns max |w|."""
    a = k[0]
    b = k[1]
    c = k[2]
    d = k[3]
    for j in range(n_out):
        row = offset + j * n_in
        total = np.float32(0.0)
        for i in range(n_in):
            total += w[row + i] * pre[i]
        total *= scale
        post_j = _tanh(total) if squash else total
        post[j] = post_j
        for i in range(n_in):
            s = row + i
            w[s] = w[s] * scale + (a[s] * post_j + b[s]) * pre[i] + (c[s] * post_j + d[s])
    largest = np.float32(0.0)
    for s in range(offset, offset + n_out * n_in):
        magnitude = abs(w[s])
        largest = magnitude if magnitude > largest else largest
    return largest


@njit(**_FLAGS)
def hebbian_forward_update(w, k, scale, obs, work, n_in, n_h1, n_h2, n_out, squash_out, normalise):
    """Act with the current weights, then apply the Hebbian update to every layer.

    ``w`` holds the three layers flat, C-order (out, in) each; ``k`` is (4, n_synapses), the folded
    coefficients in the same order; ``scale`` (3,) the pending normalisation factor per layer.
    Updating right after acting is the original order (act, step the env, update): the action
    already sent to the environment was computed with the old weights.
    """
    x = work[:n_in]
    h1 = work[n_in:n_in + n_h1]
    h2 = work[n_in + n_h1:n_in + n_h1 + n_h2]
    out = work[n_in + n_h1 + n_h2:]
    _load_input(obs, x)
    offsets = (0, n_h1 * n_in, n_h1 * n_in + n_h2 * n_h1)
    largest = _plastic_layer(w, k, offsets[0], n_h1, n_in, x, h1, scale[0], True)
    scale[0] = np.float32(1.0) / largest if normalise and largest > 0 else np.float32(1.0)
    largest = _plastic_layer(w, k, offsets[1], n_h2, n_h1, h1, h2, scale[1], True)
    scale[1] = np.float32(1.0) / largest if normalise and largest > 0 else np.float32(1.0)
    largest = _plastic_layer(w, k, offsets[2], n_out, n_h2, h2, out, scale[2], squash_out)
    scale[2] = np.float32(1.0) / largest if normalise and largest > 0 else np.float32(1.0)
