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
from policies.network import HIDDEN

# No fastmath: every sum is evaluated in the order written here, with one rounding per operation,
# whatever the CPU's vector width or its fused multiply-add (docs/reproducibility.md). The loops
# vectorise across independent outputs (a layer's units, a row's synapses), never inside one sum.
# numpy's error model: a division by zero gives IEEE's inf or NaN instead of a Python check, which
# would stop vectorisation.
_FLAGS = dict(cache=True, nogil=True, error_model="numpy")
_ABS_BITS = np.uint32(0x7FFFFFFF)
# The hidden layers' widths, constants of the compiled code: a row of 128 or 64 synapses is then a fixed
# number of vectors, with no loop bounds, remainder or pointer bookkeeping to compute per row, which had
# cost as many instructions as the row's arithmetic. Any other width (the output layer) takes the same
# loops with its width read at run time; the arithmetic is the same either way.
WIDE, NARROW = HIDDEN
_VECTOR = 16  # float32 lanes of the widest vectors (AVX-512): a narrower layer's rows are not vectorised


@njit(inline="always")
def _accumulate(weights_t, pre, post, width):
    """post[j] += W^T[i, j] * pre[i] over the rows, each of ``width`` synapses. (Rows indexed, not
    viewed, and the loop over them in here: a view, or an array passed to an inlined function, is an
    array whose reference count numba raises and lowers, two calls that had cost as much as a row of
    64 synapses.)"""
    for i in range(weights_t.shape[0]):
        activity = pre[i]
        for j in range(width):
            post[j] += weights_t[i, j] * activity


@njit(**_FLAGS)
def _dense(weights_t, pre, post, scale, squash):
    """post = act(scale * W @ pre), with ``weights_t`` = W^T of shape (n_in, n_out)."""
    n_in, n_out = weights_t.shape
    post[:] = 0.0
    if n_out == WIDE:  # (the same loop, its width a constant: see WIDE)
        _accumulate(weights_t, pre, post, WIDE)
    elif n_out == NARROW:
        _accumulate(weights_t, pre, post, NARROW)
    elif n_out >= _VECTOR:
        _accumulate(weights_t, pre, post, n_out)
    else:  # fewer outputs than a vector holds: each output's sum in turn, over the same terms in the same order
        for j in range(n_out):
            total = post[j]
            for i in range(n_in):
                total += weights_t[i, j] * pre[i]
            post[j] = total
    if squash:  # two loops rather than a branch inside one: each vectorises
        for j in range(n_out):
            post[j] = rational_tanh(post[j] * scale)
    else:
        for j in range(n_out):
            post[j] *= scale


@njit(inline="always")
def _update_rows(weights_t, folded, pre, post, scale, width, normalise):
    """The Hebbian update of every row, each of ``width`` synapses (rows indexed, as ``_accumulate``); the
    largest magnitude of the updated weights when ``normalise``, from their bits: for non-negative floats
    their order is the integers' order, and an integer max reduction vectorises where a float one does
    not (a max of uint32, 16 to a vector; a conditional expression here had widened them to 64 bits, at
    three times the instructions)."""
    bits = weights_t.view(np.uint32)
    largest = np.uint32(0)
    for i in range(weights_t.shape[0]):
        activity = pre[i]
        for j in range(width):
            weights_t[i, j] = (weights_t[i, j] * scale + (folded[0, i, j] * post[j] + folded[1, i, j]) * activity
                               + (folded[2, i, j] * post[j] + folded[3, i, j]))
        if normalise:  # the row's largest |w| while it is in the cache: a pass over the whole layer
            for j in range(width):  # afterwards cost ~17 us more in CarRacing's loop
                largest = np.uint32(max(largest, np.uint32(bits[i, j] & _ABS_BITS)))
    return largest


@njit(inline="always")
def _update_narrow(weights_t, folded, pre, post, scale, normalise):
    """The Hebbian update of a layer narrower than a vector (an output layer of a few actions), as one
    loop over all its synapses, ``post`` and ``pre`` laid out beside them first: row by row, a loop of a
    few synapses had cost some 25 instructions a synapse in loop bookkeeping. The same arithmetic per
    synapse as ``_update_rows``; returns the largest magnitude."""
    n_in, n_out = weights_t.shape
    size = n_in * n_out
    posts, pres = np.empty(size, dtype=np.float32), np.empty(size, dtype=np.float32)
    for i in range(n_in):
        for j in range(n_out):
            posts[i * n_out + j], pres[i * n_out + j] = post[j], pre[i]
    weights, bits = weights_t.reshape(size), weights_t.reshape(size).view(np.uint32)
    a, b, c, d = (folded[0].reshape(size), folded[1].reshape(size), folded[2].reshape(size),
                  folded[3].reshape(size))
    for k in range(size):
        weights[k] = weights[k] * scale + (a[k] * posts[k] + b[k]) * pres[k] + (c[k] * posts[k] + d[k])
    largest = np.uint32(0)
    if normalise:
        for k in range(size):
            largest = np.uint32(max(largest, np.uint32(bits[k] & _ABS_BITS)))
    return largest


@njit(**_FLAGS)
def _plastic(weights_t, folded, pre, post, scale, squash, normalise):
    """Forward one layer with its current weights, then update it in place; returns the factor
    that normalises the updated layer (1 / max |w|), or 1."""
    _dense(weights_t, pre, post, scale, squash)
    n_out = weights_t.shape[1]
    if n_out == WIDE:
        largest = _update_rows(weights_t, folded, pre, post, scale, WIDE, normalise)
    elif n_out == NARROW:
        largest = _update_rows(weights_t, folded, pre, post, scale, NARROW, normalise)
    elif n_out >= _VECTOR:
        largest = _update_rows(weights_t, folded, pre, post, scale, n_out, normalise)
    else:
        largest = _update_narrow(weights_t, folded, pre, post, scale, normalise)
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


# --- a network's state in one array ------------------------------------------------------------------
# A step hands the compiled code the state and the observation, two arrays: each array an entry point is
# passed costs about 1,200 instructions to check and unbox, each number about 300, which for the head's
# eleven arguments had been a tenth of a MuJoCo step's overhead in the training loop. The state array
# (float32) holds, in this order: a header of HEADER slots, the sizes and flags as int32 (n_in, n_h1, n_h2,
# n_out, squash_out, normalise) then the Hebbian layers' pending scales (3); the activities [x | h1 | h2 |
# out]; the weights, in the layout above; and for a Hebbian network its rule's planes. Each part starts at
# a multiple of 16 floats (64 bytes), as a row of weights did in an array of its own.

HEADER = 16
_ALIGN = 16
_SCALE_AT = 8


@njit(inline="always")
def _parts(n_in, n_h1, n_h2, n_out):
    """Where the activities, the weights and the rule's planes start in a state array, and their sizes."""
    units = n_in + n_h1 + n_h2 + n_out
    synapses = n_in * n_h1 + n_h1 * n_h2 + n_h2 * n_out
    weights_at = HEADER + (units + _ALIGN - 1) // _ALIGN * _ALIGN
    planes_at = weights_at + (synapses + _ALIGN - 1) // _ALIGN * _ALIGN
    return units, synapses, weights_at, planes_at


def head_state(sizes: tuple[int, int, int, int], squash_out: bool, normalise: bool = False,
               plastic: bool = False) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A zeroed state array for the head of these layer sizes (with the rule's planes if ``plastic``), and
    views of its parts: ``work`` (the activities), ``out`` (the output, their end), ``weights``, ``scale``
    (ones) and ``folded`` (if ``plastic``), for the caller to fill."""
    units, synapses, weights_at, planes_at = _parts(*sizes)
    state = np.zeros(planes_at + (4 * synapses if plastic else 0), dtype=np.float32)
    state[:6].view(np.int32)[:] = (*sizes, int(squash_out), int(normalise))
    views = {"work": state[HEADER:HEADER + units], "weights": state[weights_at:weights_at + synapses],
             "scale": state[_SCALE_AT:_SCALE_AT + 3]}
    views["out"] = views["work"][units - sizes[3]:]
    views["scale"][:] = 1.0
    if plastic:
        views["folded"] = state[planes_at:planes_at + 4 * synapses]
    return state, views


@njit(inline="always")
def _header(state):
    header = state[:6].view(np.int32)
    return header[0], header[1], header[2], header[3], header[4] != 0, header[5] != 0


@njit(**_FLAGS)
def static_step(state, obs):
    """``static_forward`` of a state array made by ``head_state``."""
    n_in, n_h1, n_h2, n_out, squash_out, _ = _header(state)
    units, synapses, weights_at, _ = _parts(n_in, n_h1, n_h2, n_out)
    static_forward(state[weights_at:weights_at + synapses], obs, state[HEADER:HEADER + units], n_in, n_h1, n_h2,
                   n_out, squash_out)


@njit(**_FLAGS)
def hebbian_step(state, obs):
    """``hebbian_forward_update`` of a state array made by ``head_state`` (``plastic``)."""
    n_in, n_h1, n_h2, n_out, squash_out, normalise = _header(state)
    units, synapses, weights_at, planes_at = _parts(n_in, n_h1, n_h2, n_out)
    hebbian_forward_update(state[weights_at:weights_at + synapses], state[planes_at:planes_at + 4 * synapses],
                           state[_SCALE_AT:_SCALE_AT + 3], obs, state[HEADER:HEADER + units], n_in, n_h1, n_h2,
                           n_out, squash_out, normalise)
