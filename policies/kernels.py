"""Compiled per-step kernels: the dense three-layer head, static and Hebbian.

Every network of the project ends in the same head, in -> 128 -> 64 -> out without biases
(Najarro & Risi 2020; docs/original.md, "Networks"). One call per environment step runs the whole
head, so the interpreter is crossed once per step instead of a dozen times.

Layout. Each layer is stored transposed, as W^T with shape (n_in, n_out), C-order, the three
layers one after the other in one flat float32 array. The forward pass is then a sum of rows
(``post += pre[i] * W^T[i]``) and the Hebbian update a loop over rows, both contiguous in the
inner loop, which the compiler vectorises. It is also the original coefficient layout: the
coefficients of synapse (pre i, post j) are row ``layer_offset + i * n_out + j`` (docs/original.md, "Networks"),
the same position as the weight.

The Hebbian update is evaluated in a folded form. Every rule of the paper is an instance of
    dw_ij = eta * (A o_i o_j + B o_i + C o_j + D_in) + D_out
which, per synapse, is  (a o_j + b) o_i + c o_j + d  with a = eta A, b = eta B, c = eta C and
d = eta D_in + D_out (see ``policies.rules``). The folding happens once per episode, so the kernel
reads four coefficients per synapse whatever the rule: per layer, four planes (a, b, c, d) of
shape (n_in, n_out), stored one layer after the other.

Weight normalisation (each layer divided by its largest |w| after every update, docs/original.md, "Hebbian rules") is
kept lazy: a layer's stored weights times ``scale[layer]`` are its true weights, so the division
is folded into the next step's pass over the layer. A layer whose weights are all zero is left as
it is instead of turning into NaN.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from policies.elementary import rational_tanh

# No fastmath: every sum is evaluated in the order written here, with one rounding per operation,
# whatever the CPU's vector width or its fused multiply-add (docs/reproducibility.md). The loops
# vectorise across independent outputs (a layer's units, a row's synapses), never inside one sum.
# numpy's error model: a division by zero gives IEEE's inf or NaN instead of a Python check, which
# would stop vectorisation.
_FLAGS = dict(cache=True, nogil=True, error_model="numpy")
_ABS_BITS = np.uint32(0x7FFFFFFF)


@njit(**_FLAGS)
def _dense(weights_t, pre, post, scale, squash):
    """post = act(scale * W @ pre), with ``weights_t`` = W^T of shape (n_in, n_out)."""
    n_in, n_out = weights_t.shape
    post[:] = 0.0
    for i in range(n_in):
        activity = pre[i]
        row = weights_t[i]
        for j in range(n_out):
            post[j] += row[j] * activity
    if squash:  # two loops rather than a branch inside one: each vectorises
        for j in range(n_out):
            post[j] = rational_tanh(post[j] * scale)
    else:
        for j in range(n_out):
            post[j] *= scale


@njit(inline="always")
def _largest_bits(bits, largest):
    """The largest of ``largest`` and the magnitudes of the float32 whose bit patterns are ``bits``:
    for non-negative floats their order is the integers' order, and an integer max reduction
    vectorises where a float one does not."""
    for index in range(bits.shape[0]):
        magnitude = bits[index] & _ABS_BITS
        largest = magnitude if magnitude > largest else largest
    return largest


@njit(**_FLAGS)
def _plastic(weights_t, folded, pre, post, scale, squash, normalise):
    """Forward one layer with its current weights, then update it in place; returns the factor
    that normalises the updated layer (1 / max |w|), or 1."""
    _dense(weights_t, pre, post, scale, squash)
    n_in, n_out = weights_t.shape
    bits = weights_t.view(np.uint32)
    largest = np.uint32(0)
    for i in range(n_in):
        activity = pre[i]
        row = weights_t[i]
        a = folded[0, i]
        b = folded[1, i]
        c = folded[2, i]
        d = folded[3, i]
        for j in range(n_out):
            row[j] = row[j] * scale + (a[j] * post[j] + b[j]) * activity + (c[j] * post[j] + d[j])
        if normalise:  # the row's largest |w| while it is in the cache: a pass over the whole layer
            largest = _largest_bits(bits[i], largest)  # afterwards cost ~17 us more in CarRacing's loop
    one = np.float32(1.0)
    if not normalise:
        return one
    found = np.empty(1, dtype=np.uint32)
    found[0] = largest
    magnitude = found.view(np.float32)[0]
    return one / magnitude if magnitude > 0 else one


@njit(**_FLAGS)
def _activities(obs, work, n_in, n_h1, n_h2):
    """Copy the observation into ``work`` = [x | h1 | h2 | out] and return the four views."""
    for i in range(n_in):
        work[i] = np.float32(obs[i])
    h2_start = n_in + n_h1
    out_start = h2_start + n_h2
    return work[:n_in], work[n_in:h2_start], work[h2_start:out_start], work[out_start:]


@njit(**_FLAGS)
def static_forward(weights, obs, work, n_in, n_h1, n_h2, n_out, squash_out):
    """The static head. ``work`` holds [x | h1 | h2 | out]; the output is its last ``n_out`` values."""
    one = np.float32(1.0)
    o2 = n_in * n_h1
    o3 = o2 + n_h1 * n_h2
    x, h1, h2, out = _activities(obs, work, n_in, n_h1, n_h2)
    _dense(weights[:o2].reshape(n_in, n_h1), x, h1, one, True)
    _dense(weights[o2:o3].reshape(n_h1, n_h2), h1, h2, one, True)
    _dense(weights[o3:].reshape(n_h2, n_out), h2, out, one, squash_out)


@njit(**_FLAGS)
def hebbian_forward_update(weights, folded, scale, obs, work, n_in, n_h1, n_h2, n_out, squash_out, normalise):
    """Act with the current weights, then apply the Hebbian update to every layer.

    ``folded`` holds, per layer, the planes (a, b, c, d) of shape (n_in, n_out); ``scale`` (3,) the
    pending normalisation factor of each layer. Updating right after acting is the original
    order (act, step the environment, update): the action was computed with the old weights.
    """
    o2 = n_in * n_h1
    o3 = o2 + n_h1 * n_h2
    x, h1, h2, out = _activities(obs, work, n_in, n_h1, n_h2)
    scale[0] = _plastic(weights[:o2].reshape(n_in, n_h1), folded[:4 * o2].reshape(4, n_in, n_h1),
                        x, h1, scale[0], True, normalise)
    scale[1] = _plastic(weights[o2:o3].reshape(n_h1, n_h2), folded[4 * o2:4 * o3].reshape(4, n_h1, n_h2),
                        h1, h2, scale[1], True, normalise)
    scale[2] = _plastic(weights[o3:].reshape(n_h2, n_out), folded[4 * o3:].reshape(4, n_h2, n_out),
                        h2, out, scale[2], squash_out, normalise)
