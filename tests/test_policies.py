"""Static and Hebbian policies (policies/) against references written from docs/original.md ("Networks",
"Initial weights" and "Hebbian rules").

- the fused numba Hebbian kernel, step by step, against a numpy reference of docs/original.md, "Hebbian rules"
  (act with the current weights, update each layer from its own pre/post activities, normalise);
- a Hebbian net with zero coefficients acts exactly like the static net on the same weights;
- the static flat vector is PyTorch's ``parameters_to_vector`` order of the original modules (MLP and
  CNN), checked against a torch forward pass; the CNN's pooling is torch's, bit for bit;
- the ``--init_weights`` distributions of docs/original.md, "Initial weights", per-episode reproducibility;
- the parameter counts of docs/original.md, "Networks", the named layout, and export/load in the original shapes.
"""

import math

import numpy as np
import pytest
import torch
from torch import nn

from envs import episode_rng
from policies.hebbian import HebbianPolicy
from policies.init import INIT_WEIGHTS
from policies.network import NetworkSpec
from policies.rules import RULES
from policies.static import StaticPolicy
from tests.rule_equations import EQUATIONS

MLP = NetworkSpec((5,), 3)
PIXELS = NetworkSpec((3, 84, 84), 3)
CAR = PIXELS
ANT = NetworkSpec((28,), 8)

def reference_episode(rule, coeffs, weights, observations, squash_out, normalise):
    """The original's step (docs/original.md, "Hebbian rules") in float64: act, then update every layer, then
    divide each by its max |w|.

    ``coeffs`` is (n_synapses, k) with row offset + i * n_out + j for the synapse i -> j of a layer;
    ``weights`` the (n_out, n_in) layers, updated in place. Returns the output of every step.
    """
    outputs = []
    for obs in observations:
        activities = [np.asarray(obs, dtype=np.float64)]
        for layer, w in enumerate(weights):
            z = w @ activities[-1]
            activities.append(np.tanh(z) if layer < 2 or squash_out else z)
        outputs.append(activities[-1])
        offset = 0
        for layer, w in enumerate(weights):
            n_out, n_in = w.shape
            block = coeffs[offset:offset + n_in * n_out]  # rows in (i, j) order
            h = block.reshape(n_in, n_out, -1).transpose(2, 1, 0)  # h[c][j, i]
            pre, post = activities[layer][None, :], activities[layer + 1][:, None]
            w += EQUATIONS[rule](h, pre, post)
            offset += n_in * n_out
        if normalise:
            for w in weights:
                w /= np.abs(w).max()
    return outputs


# --- (a) the fused Hebbian kernel against the reference -------------------------------------------


@pytest.mark.parametrize("normalise", [True, False], ids=["normalised", "raw"])
@pytest.mark.parametrize("squash_out", [False, True], ids=["linear_out", "tanh_out"])
@pytest.mark.parametrize("rule", list(RULES))
def test_hebbian_kernel_matches_the_reference(rule, squash_out, normalise):
    net = NetworkSpec((5,), 3, squash_out=squash_out)
    policy = HebbianPolicy(net, rule=rule, init_weights="uni", normalise=normalise)
    rng = np.random.default_rng([len(rule), squash_out, normalise])
    # Unnormalised weights grow step by step: keep the coefficients small so they stay O(1).
    scale = 1.0 if normalise else 0.1
    params = (scale * rng.standard_normal(policy.num_params)).astype(np.float32)
    observations = rng.uniform(-2, 2, size=(6, 5))

    state = policy.reset(params, episode_rng(11))
    weights = [w.astype(np.float64) for w in state.layer_weights(net)]
    coeffs = policy.layout.view(params, "coefficients").astype(np.float64)
    expected_outputs = reference_episode(rule, coeffs, weights, observations, squash_out, normalise)

    for step, obs in enumerate(observations):
        output, state = policy.act(params, state, obs)
        np.testing.assert_allclose(output, expected_outputs[step], rtol=1e-4, atol=1e-5,
                                   err_msg=f"output at step {step}")
    for layer, (actual, expected) in enumerate(zip(state.layer_weights(net), weights)):
        assert actual.shape == expected.shape
        np.testing.assert_allclose(actual, expected, rtol=1e-4, atol=1e-5 * np.abs(expected).max(),
                                   err_msg=f"layer {layer} weights")
        if normalise:
            assert np.abs(actual).max() == pytest.approx(1.0, rel=1e-6)


def test_first_action_uses_the_initial_weights():
    # The update comes after acting (docs/original.md, "Hebbian rules"): step 0 sees the episode's initial weights only.
    policy = HebbianPolicy(MLP, rule="ABCD_lr", init_weights="uni")
    params = np.random.default_rng(0).standard_normal(policy.num_params).astype(np.float32)
    state = policy.reset(params, episode_rng(3))
    w1, w2, w3 = [w.astype(np.float64) for w in state.layer_weights(MLP)]
    obs = np.array([0.5, -1.0, 0.25, 2.0, -0.75])
    output, _ = policy.act(params, state, obs)
    np.testing.assert_allclose(output, w3 @ np.tanh(w2 @ np.tanh(w1 @ obs)), rtol=1e-5, atol=1e-6)


# --- (b) zero coefficients: a Hebbian net is its static net ---------------------------------------


@pytest.mark.parametrize("net", [MLP, NetworkSpec((5,), 3, squash_out=True), PIXELS], ids=["mlp", "mlp_tanh", "cnn"])
def test_zero_coefficients_act_exactly_like_the_static_net(net):
    hebbian = HebbianPolicy(net, rule="ABCD_lr_D_in_and_out", init_weights="coevolve", normalise=False)
    static = StaticPolicy(net)
    rng = np.random.default_rng(2)
    weights = static.initial_params(rng)
    params = np.zeros(hebbian.num_params, dtype=np.float32)
    params[hebbian.layout["initial_weights"].slice] = weights
    hebbian_state, static_state = hebbian.reset(params, None), static.reset(weights)
    for _ in range(4):
        obs = rng.uniform(0, 1, size=net.obs_shape)
        hebbian_out = hebbian.act(params, hebbian_state, obs)[0].copy()
        static_out = static.act(weights, static_state, obs)[0].copy()
        np.testing.assert_array_equal(hebbian_out, static_out)
    assert np.abs(static_out).max() > 0  # a real output, not two zero vectors


# --- (c) the static vector is PyTorch's parameter order -------------------------------------------


class TorchMLP(nn.Module):
    """The original MLP (docs/original.md, "Networks"): no biases, tanh hidden layers, raw or tanh output."""

    def __init__(self, n_in, n_actions, squash_out):
        super().__init__()
        self.linear1 = nn.Linear(n_in, 128, bias=False)
        self.linear2 = nn.Linear(128, 64, bias=False)
        self.out = nn.Linear(64, n_actions, bias=False)
        self.squash_out = squash_out

    def forward(self, x):
        out = self.out(torch.tanh(self.linear2(torch.tanh(self.linear1(x)))))
        return torch.tanh(out) if self.squash_out else out


class TorchCNN(nn.Module):
    """The original CNN (docs/original.md, "Networks"): one pool module used twice, flatten with view(-1)."""

    def __init__(self, n_actions):
        super().__init__()
        self.cnn_1 = nn.Conv2d(3, 6, 3, stride=1, bias=False)
        self.cnn_2 = nn.Conv2d(6, 8, 5, stride=2, bias=False)
        self.pool = nn.MaxPool2d(2, 2)
        self.linear1 = nn.Linear(648, 128, bias=False)
        self.linear2 = nn.Linear(128, 64, bias=False)
        self.out = nn.Linear(64, n_actions, bias=False)

    def forward(self, obs):
        x = self.pool(torch.tanh(self.cnn_1(obs)))
        x = self.pool(torch.tanh(self.cnn_2(x))).view(-1)
        return self.out(torch.tanh(self.linear2(torch.tanh(self.linear1(x)))))


@pytest.mark.parametrize("squash_out", [False, True])
def test_static_mlp_vector_is_torch_parameter_order(squash_out):
    net = NetworkSpec((28,), 8, squash_out=squash_out)
    module = TorchMLP(28, 8, squash_out)
    policy = StaticPolicy(net)
    vector = np.random.default_rng(4).normal(0, 0.3, policy.num_params).astype(np.float32)
    nn.utils.vector_to_parameters(torch.from_numpy(vector.copy()), module.parameters())
    assert [tuple(p.shape) for p in module.parameters()] == [part.shape for part in policy.layout.parts.values()]

    state = policy.reset(vector)
    for obs in np.random.default_rng(5).normal(size=(3, 28)).astype(np.float32):
        with torch.no_grad():
            expected = module(torch.from_numpy(obs)).numpy()
        output, state = policy.act(vector, state, obs)
        np.testing.assert_allclose(output, expected, rtol=1e-5, atol=1e-6)


def test_static_cnn_vector_is_torch_parameter_order():
    module = TorchCNN(3)
    policy = StaticPolicy(PIXELS)
    assert list(policy.layout.parts) == ["conv1", "conv2", "fc1", "fc2", "fc3"]
    assert [tuple(p.shape) for p in module.parameters()] == [part.shape for part in policy.layout.parts.values()]
    # PyTorch's default scale, U(+-1/sqrt(fan_in)) per layer, so the conv features are not saturated.
    vector = policy.initial_params(np.random.default_rng(7))
    assert vector.size == policy.num_params == 92_690
    nn.utils.vector_to_parameters(torch.from_numpy(vector.copy()), module.parameters())
    np.testing.assert_array_equal(module.cnn_2.weight.detach().numpy().ravel(), vector[162:1362])

    state = policy.reset(vector)
    for obs in np.random.default_rng(6).uniform(0, 1, size=(2, 3, 84, 84)).astype(np.float32):
        with torch.no_grad():
            expected = module(torch.from_numpy(obs)[None]).numpy()
        output, state = policy.act(vector, state, obs)
        np.testing.assert_allclose(output, expected, rtol=1e-4, atol=1e-6)



@pytest.mark.parametrize("shape", [(6, 82, 82), (8, 19, 19)])
def test_max_pool2_is_torchs_max_pool2d_bit_for_bit(shape):
    """The CNN's pooling (policies/conv.py) must not move a bit: signed zeros, NaN payloads, infinities."""
    from policies.conv import max_pool2

    rng = np.random.default_rng(sum(shape))
    planes = rng.normal(size=shape).astype(np.float32)
    flat = planes.reshape(-1)
    special = rng.choice(flat.size, size=flat.size // 2, replace=False)
    flat[special] = rng.choice(np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1.0], dtype=np.float32), size=special.size)
    nans = np.flatnonzero(np.isnan(flat))
    flat.view(np.uint32)[nans] |= rng.integers(1, 1 << 22, size=nans.size).astype(np.uint32)  # distinct payloads
    with torch.inference_mode():
        expected = nn.functional.max_pool2d(torch.from_numpy(planes)[None], 2)[0].numpy()
    assert np.array_equal(max_pool2(planes).view(np.uint32), expected.view(np.uint32))


@pytest.mark.parametrize("channels", [3, 4])
def test_default_cnn_features_are_torchs_layers_to_float32_rounding(channels):
    """The default front end (policies/conv.py: the ordered kernels, the project's tanh) gives torch's own
    layers' features within 1e-5 (the tanh's few ulps, carried through conv2), and overwrites one array
    at every call."""
    from policies.conv import ConvFeatures
    from policies.network import conv_shapes

    shapes = conv_shapes(channels)
    rng = np.random.default_rng(channels)
    weights = rng.normal(0.0, 0.5, sum(int(np.prod(shape)) for shape in shapes)).astype(np.float32)
    conv1, conv2 = (torch.from_numpy(part.reshape(shape)) for part, shape in
                    zip(np.split(weights, [int(np.prod(shapes[0]))]), shapes))
    features = ConvFeatures(weights, shapes)
    first = None
    for obs in rng.uniform(0, 1, size=(3, channels, 84, 84)).astype(np.float32):
        with torch.inference_mode():
            x = nn.functional.max_pool2d(torch.tanh(nn.functional.conv2d(torch.from_numpy(obs)[None], conv1)), 2)
            expected = nn.functional.max_pool2d(torch.tanh(nn.functional.conv2d(x, conv2, stride=2)), 2).reshape(-1)
        got = features(obs)
        first = got if first is None else first
        assert got is first and np.abs(got - expected.numpy()).max() < 1e-5

# --- (d) --init_weights distributions (docs/original.md, "Initial weights") ----------------------------------

# (kind, parameter) of each distribution for a layer with the given fan-in and fan-out.
SPEC_INIT = {
    "uni": lambda fan_in, fan_out: ("uniform", 0.1),
    "normal": lambda fan_in, fan_out: ("normal", 0.024),
    "default": lambda fan_in, fan_out: ("uniform", 1 / math.sqrt(fan_in)),
    "xa_uni": lambda fan_in, fan_out: ("uniform", 0.3 * math.sqrt(6 / (fan_in + fan_out))),
    "xa_uni_big": lambda fan_in, fan_out: ("uniform", math.sqrt(6 / (fan_in + fan_out))),
    "ka_uni": lambda fan_in, fan_out: ("uniform", math.sqrt(0.6 / fan_in)),
    "uni_big": lambda fan_in, fan_out: ("uniform", 1.0),
    "sparse": lambda fan_in, fan_out: ("sparse", 0.01),
    "ones": lambda fan_in, fan_out: ("constant", 1.0),
    "zeros": lambda fan_in, fan_out: ("constant", 0.0),
}


def test_every_init_choice_is_specified():
    assert set(INIT_WEIGHTS) == set(SPEC_INIT)


def test_spec_bounds_for_ant_and_car_first_layers():
    # The numbers quoted in docs/original.md, "Initial weights" (Ant fc1: 28 -> 128; Car linear1: 648 -> 128).
    assert SPEC_INIT["xa_uni"](28, 128)[1] == pytest.approx(0.0588, abs=1e-4)
    assert SPEC_INIT["xa_uni"](648, 128)[1] == pytest.approx(0.0264, abs=1e-4)
    assert SPEC_INIT["xa_uni_big"](28, 128)[1] == pytest.approx(0.196, abs=1e-3)
    assert SPEC_INIT["xa_uni_big"](648, 128)[1] == pytest.approx(0.0879, abs=1e-4)
    assert SPEC_INIT["ka_uni"](28, 128)[1] == pytest.approx(0.146, abs=1e-3)
    assert SPEC_INIT["ka_uni"](648, 128)[1] == pytest.approx(0.0304, abs=1e-4)
    assert SPEC_INIT["default"](28, 128)[1] == pytest.approx(0.189, abs=1e-3)


def check_distribution(weights, kind, value):
    if kind == "uniform":
        assert np.abs(weights).max() <= value * (1 + 1e-6)
        assert np.abs(weights).max() >= 0.95 * value
        assert weights.std() == pytest.approx(value / math.sqrt(3), rel=0.08)
        assert abs(weights.mean()) < 0.1 * value
    elif kind == "normal":
        assert weights.std() == pytest.approx(value, rel=0.08)
        assert np.abs(weights).max() > 2 * value  # not a uniform of the same scale
    elif kind == "sparse":
        n_zeros = math.ceil(0.8 * weights.shape[0])
        np.testing.assert_array_equal((weights == 0).sum(axis=0), n_zeros)
        assert weights[weights != 0].std() == pytest.approx(value, rel=0.15)
    else:
        np.testing.assert_array_equal(weights, value)


@pytest.mark.parametrize("name", list(SPEC_INIT))
def test_init_weights_follow_the_spec(name):
    policy = HebbianPolicy(ANT, rule="A", init_weights=name)
    params = np.zeros(policy.num_params, dtype=np.float32)
    layers = policy.reset(params, episode_rng(21)).layer_weights(ANT)
    assert [w.shape for w in layers] == [(128, 28), (64, 128), (8, 64)]
    for w in layers:
        assert w.dtype == np.float32
        fan_out, fan_in = w.shape
        check_distribution(w, *SPEC_INIT[name](fan_in, fan_out))


@pytest.mark.parametrize("name", list(SPEC_INIT))
def test_init_weights_reproducible_per_episode_seed(name):
    policy = HebbianPolicy(ANT, rule="A", init_weights=name)
    params = np.zeros(policy.num_params, dtype=np.float32)

    def first_layer(seed):
        return policy.reset(params, episode_rng(seed)).layer_weights(ANT)[0]

    np.testing.assert_array_equal(first_layer(5), first_layer(5))
    if name not in ("ones", "zeros"):
        assert not np.array_equal(first_layer(5), first_layer(6))


# --- (e) parameter counts and layout (docs/original.md, "Networks") ------------------------------------------


def test_static_parameter_counts():
    assert StaticPolicy(CAR).num_params == 92_690
    assert StaticPolicy(ANT).num_params == 12_288
    assert StaticPolicy(CAR).layout.describe() == {
        "conv1": [6, 3, 3, 3], "conv2": [8, 6, 5, 5], "fc1": [128, 648], "fc2": [64, 128], "fc3": [3, 64]}
    assert StaticPolicy(ANT).layout.describe() == {"fc1": [128, 28], "fc2": [64, 128], "fc3": [8, 64]}


@pytest.mark.parametrize("rule, car_coeffs, ant_coeffs", [
    ("A", 91_328, 12_288), ("AD", 182_656, 24_576), ("AD_lr", 273_984, 36_864), ("ABC", 273_984, 36_864),
    ("ABC_lr", 365_312, 49_152), ("ABCD", 365_312, 49_152), ("ABCD_lr", 456_640, 61_440),
    ("ABCD_lr_D_out", 456_640, 61_440), ("ABCD_lr_D_in_and_out", 547_968, 73_728)])
def test_hebbian_parameter_counts(rule, car_coeffs, ant_coeffs):
    car = HebbianPolicy(CAR, rule=rule)
    assert car.layout["coefficients"].size == car_coeffs
    assert car.layout["cnn"].size == 1_362
    assert car.num_params == car_coeffs + 1_362
    assert car.penalised == car.layout["coefficients"].slice  # the L2 term covers coefficients only
    ant = HebbianPolicy(ANT, rule=rule)
    assert ant.num_params == ant.layout["coefficients"].size == ant_coeffs
    assert list(ant.layout.parts) == ["coefficients"]


def test_hebbian_layout_names_its_parts():
    car = HebbianPolicy(CAR, rule="ABCD_lr")
    assert car.num_params == 458_002
    assert car.layout.describe() == {"coefficients": [91_328, 5], "cnn": [1_362]}
    assert (car.layout["cnn"].offset, car.layout["cnn"].size) == (456_640, 1_362)
    assert CAR.n_synapses == 91_328 and ANT.n_synapses == 12_288
    car_coevolved = HebbianPolicy(CAR, rule="ABCD_lr", init_weights="coevolve")
    assert car_coevolved.layout.describe() == {"coefficients": [91_328, 5], "initial_weights": [92_690]}
    ant_coevolved = HebbianPolicy(ANT, rule="ABCD_lr", init_weights="coevolve")
    assert ant_coevolved.layout.describe() == {"coefficients": [12_288, 5], "initial_weights": [12_288]}
    assert ant_coevolved.num_params == 61_440 + 12_288


# --- (f) export and load in the original shapes ---------------------------------------------------


def random_params(policy, seed=0):
    return np.random.default_rng(seed).standard_normal(policy.num_params).astype(np.float32)


def test_rule_a_exports_a_vector_and_loads_both_original_shapes():
    policy = HebbianPolicy(ANT, rule="A")
    params = random_params(policy)
    arrays = policy.export(params)
    assert list(arrays) == ["coeffs"]
    assert arrays["coeffs"].shape == (12_288,)
    np.testing.assert_array_equal(policy.load(arrays), params)
    # the original's uniform distribution wrote rule A as (n_syn, 1)
    np.testing.assert_array_equal(policy.load({"coeffs": arrays["coeffs"][:, None]}), params)


@pytest.mark.parametrize("rule", [name for name, rule in RULES.items() if rule.n_coeffs > 1])
def test_rules_with_several_coefficients_export_a_matrix(rule):
    policy = HebbianPolicy(MLP, rule=rule)
    params = random_params(policy)
    arrays = policy.export(params)
    assert arrays["coeffs"].shape == (MLP.n_synapses, RULES[rule].n_coeffs)
    np.testing.assert_array_equal(policy.load(arrays), params)


def test_pixel_and_coevolved_round_trips():
    pixel = HebbianPolicy(CAR, rule="ABCD_lr")
    params = random_params(pixel)
    arrays = pixel.export(params)
    assert {name: a.shape for name, a in arrays.items()} == {"coeffs": (91_328, 5), "CNN_parameters": (1_362,)}
    np.testing.assert_array_equal(pixel.load(arrays), params)
    # the original's uniform distribution wrote the CNN vector as a (1362, 1) column
    column = dict(arrays, CNN_parameters=arrays["CNN_parameters"][:, None])
    np.testing.assert_array_equal(pixel.load(column), params)

    coevolved = HebbianPolicy(ANT, rule="ABCD_lr", init_weights="coevolve")
    params = random_params(coevolved, seed=1)
    arrays = coevolved.export(params)
    assert {name: a.shape for name, a in arrays.items()} == {
        "coeffs": (12_288, 5), "coevolved_initial_weights": (12_288,)}
    np.testing.assert_array_equal(coevolved.load(arrays), params)


def test_static_export_and_load():
    policy = StaticPolicy(ANT)
    params = random_params(policy)
    arrays = policy.export(params)
    assert arrays["weights"].shape == (12_288,) and arrays["weights"].dtype == np.float32
    np.testing.assert_array_equal(policy.load(arrays), params)
    with pytest.raises(ValueError, match=r"\(12288,\)"):
        policy.load({"weights": np.zeros(12_289, dtype=np.float32)})


def test_load_errors_name_the_expected_shape():
    policy = HebbianPolicy(ANT, rule="ABCD_lr")
    with pytest.raises(ValueError, match=r"\(12288, 4\).*ABCD_lr.*\(12288, 5\)"):
        policy.load({"coeffs": np.zeros((12_288, 4), dtype=np.float32)})
    with pytest.raises(ValueError, match=r"\(12288, 5\)"):
        policy.load({"coeffs": np.zeros(12_288 * 5, dtype=np.float32)})
    rule_a = HebbianPolicy(ANT, rule="A")
    with pytest.raises(ValueError, match=r"\(12288, 1\) or \(12288,\)"):
        rule_a.load({"coeffs": np.zeros(100, dtype=np.float32)})


def test_pixel_net_without_its_cnn_file_asks_for_path_coev():
    policy = HebbianPolicy(CAR, rule="ABCD_lr")
    coeffs = policy.export(random_params(policy))["coeffs"]
    with pytest.raises(ValueError, match="--path_coev"):
        policy.load({"coeffs": coeffs})
    with pytest.raises(ValueError, match=r"\(1362,\)"):
        policy.load({"coeffs": coeffs, "CNN_parameters": np.zeros(1_000, dtype=np.float32)})
