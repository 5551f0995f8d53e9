"""The compiled head (``policies.kernels``) against plain loops written from its equations, bit for bit.

A layer takes one of three paths: the hidden widths (128, 64) compiled as constants, any other width of a
vector or more, and a layer narrower than a vector (an output layer of a few actions) updated as one flat
loop. Each must give the float32 operations of the equations in their order, so each is compared here with
a loop of numpy float32 scalars, one rounding per operation; and the state array's entry points
(``hebbian_step``, ``static_step``) with the functions they call on separate arrays.
"""

from __future__ import annotations

import numpy as np
import pytest

from policies import kernels
from policies.elementary import rational_tanh

F32 = np.float32


def reference_forward(weights_t, pre, scale, squash):
    """post[j] = act(scale * sum_i W^T[i, j] pre[i]), summed from +0 in the order of i."""
    n_in, n_out = weights_t.shape
    post = np.zeros(n_out, dtype=np.float32)
    for j in range(n_out):
        total = F32(0.0)
        for i in range(n_in):
            total = F32(total + F32(weights_t[i, j] * pre[i]))
        post[j] = rational_tanh(F32(total * scale)) if squash else F32(total * scale)
    return post


def reference_update(weights_t, folded, pre, post, scale, normalise):
    """w = w * scale + (a post + b) pre + (c post + d), then 1 / max |w| (or 1)."""
    n_in, n_out = weights_t.shape
    updated = np.empty_like(weights_t)
    for i in range(n_in):
        for j in range(n_out):
            a, b, c, d = (folded[k, i, j] for k in range(4))
            left = F32(F32(weights_t[i, j] * scale) + F32(F32(F32(a * post[j]) + b) * pre[i]))
            updated[i, j] = F32(left + F32(F32(c * post[j]) + d))
    if not normalise:
        return updated, F32(1.0)
    largest = np.abs(updated).max()
    return updated, F32(F32(1.0) / largest) if largest > 0 else F32(1.0)


@pytest.mark.parametrize("shape", [(9, 128), (128, 64), (6, 20), (64, 7), (3, 1)],
                         ids=["wide", "narrow", "other width", "narrower than a vector", "one unit"])
@pytest.mark.parametrize("squash", [True, False])
@pytest.mark.parametrize("normalise", [True, False])
def test_a_layer_is_its_equations_bit_for_bit(shape, squash, normalise):
    rng = np.random.default_rng([*shape, squash, normalise])
    weights_t = rng.uniform(-1, 1, shape).astype(np.float32)
    folded = (0.1 * rng.standard_normal((4, *shape))).astype(np.float32)
    pre = rng.uniform(-1, 1, shape[0]).astype(np.float32)
    scale = F32(0.75)

    post = np.empty(shape[1], dtype=np.float32)
    kernels._dense(weights_t.copy(), pre, post, scale, squash)
    expected_post = reference_forward(weights_t, pre, scale, squash)
    assert np.array_equal(post.view(np.uint32), expected_post.view(np.uint32))

    plastic, post = weights_t.copy(), np.empty(shape[1], dtype=np.float32)
    new_scale = kernels._plastic(plastic, folded, pre, post, scale, squash, normalise)
    expected, expected_scale = reference_update(weights_t, folded, pre, expected_post, scale, normalise)
    assert np.array_equal(plastic.view(np.uint32), expected.view(np.uint32))
    assert np.float32(new_scale).view(np.uint32) == expected_scale.view(np.uint32)


@pytest.mark.parametrize("width", [64, 7])
def test_a_nan_weight_is_kept_and_leaves_the_scale_at_one(width):
    """The largest magnitude is found from the bits, where a NaN is the largest: its scale 1 / NaN is not
    positive, so the layer's scale is 1, as the equations' ``1 / max |w| if max |w| > 0 else 1`` say."""
    weights_t = np.ones((4, width), dtype=np.float32)
    folded = np.zeros((4, 4, width), dtype=np.float32)
    folded[3, 2, 5] = np.nan
    post = np.empty(width, dtype=np.float32)
    scale = kernels._plastic(weights_t, folded, np.ones(4, np.float32), post, F32(1.0), True, True)
    assert scale == 1.0 and np.isnan(weights_t[2, 5]) and np.isnan(weights_t).sum() == 1


@pytest.mark.parametrize("sizes, squash_out", [((17, 128, 64, 6), True), ((648, 128, 64, 3), False),
                                               ((5, 128, 64, 20), True)])
def test_the_state_array_runs_the_same_head(sizes, squash_out):
    """``hebbian_step`` and ``static_step`` on a ``head_state`` array give, step after step, what
    ``hebbian_forward_update`` and ``static_forward`` give on separate arrays."""
    rng = np.random.default_rng(sum(sizes))
    synapses = sizes[0] * sizes[1] + sizes[1] * sizes[2] + sizes[2] * sizes[3]
    weights = rng.uniform(-1, 1, synapses).astype(np.float32)
    folded = (0.05 * rng.standard_normal(4 * synapses)).astype(np.float32)
    state, views = kernels.head_state(sizes, squash_out, normalise=True, plastic=True)
    views["weights"][:], views["folded"][:] = weights, folded
    static, static_views = kernels.head_state(sizes, squash_out)
    static_views["weights"][:] = weights
    separate, scale, work = weights.copy(), np.ones(3, dtype=np.float32), np.zeros(sum(sizes), dtype=np.float32)
    static_work = np.zeros(sum(sizes), dtype=np.float32)
    for _ in range(4):
        obs = rng.uniform(-2, 2, sizes[0])
        kernels.hebbian_step(state, obs)
        kernels.hebbian_forward_update(separate, folded, scale, obs, work, *sizes, squash_out, True)
        assert np.array_equal(views["work"].view(np.uint32), work.view(np.uint32))
        assert np.array_equal(views["weights"].view(np.uint32), separate.view(np.uint32))
        assert np.array_equal(views["scale"], scale)
        kernels.static_step(static, obs)
        kernels.static_forward(weights, obs, static_work, *sizes, squash_out)
        assert np.array_equal(static_views["out"].view(np.uint32), static_work[-sizes[3]:].view(np.uint32))
    assert np.shares_memory(views["out"], state) and views["out"].size == sizes[3]
