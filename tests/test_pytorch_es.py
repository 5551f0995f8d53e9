"""pytorch-es's networks, preprocessing and NES utilities, against references written from docs/original.md
("pytorch-es").

- the small net and the conv-LSTM against plain torch ``nn.Module`` forwards written from that page,
  loaded from our flat vector in ``state_dict`` order, step by step (the LSTM state carried by
  ``act``, zeroed by ``reset``); their parameter counts (4 610 on CartPole, 588 710 on Pong);
- their refusals (the small net on images, the conv-LSTM on vectors), in one line;
- the 42 x 42 frame and the running normalisation against a transcription of docs/original.md, "pytorch-es", and the
  normalisation restarting at every reset;
- the NES utilities (docs/original.md, "pytorch-es") against the original's loop, and exact values;
- the default CNN on a 4-frame stack against a torch forward (the RGB path is pinned elsewhere).
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces
from torch import nn

from envs.pytorch_es import ATARI_CROP, PytorchESFrame, RunningNormalisation
from es.nes import nes_utilities
from policies.network import NetworkSpec
from policies.pytorch_es import ConvLSTMPolicy, SmallNetPolicy
from policies.static import StaticPolicy

PONG_FRAMES = NetworkSpec((1, 42, 42), 6)
CARTPOLE = NetworkSpec((4,), 2)


def selu(x):
    return 1.0507009873554804934193349852946 * nn.functional.elu(x, 1.6732632423543772848170429916717)


class TorchSmallNet(nn.Module):
    """pytorch-es's small net (docs/original.md, "pytorch-es")."""

    def __init__(self, n_in, n_actions):
        super().__init__()
        self.linear1 = nn.Linear(n_in, 64)
        self.linear2 = nn.Linear(64, 64)
        self.actor_linear = nn.Linear(64, n_actions)

    def forward(self, x):
        return self.actor_linear(selu(self.linear2(selu(self.linear1(x)))))


class TorchConvLSTM(nn.Module):
    """pytorch-es's big net (docs/original.md, "pytorch-es"): four stride-2 convs with selu, LSTMCell(288,
    256), a linear head."""

    def __init__(self, channels, n_actions):
        super().__init__()
        self.conv1 = nn.Conv2d(channels, 32, 3, stride=2, padding=1)
        self.conv2 = nn.Conv2d(32, 32, 3, stride=2, padding=1)
        self.conv3 = nn.Conv2d(32, 32, 3, stride=2, padding=1)
        self.conv4 = nn.Conv2d(32, 32, 3, stride=2, padding=1)
        self.lstm = nn.LSTMCell(32 * 3 * 3, 256)
        self.actor_linear = nn.Linear(256, n_actions)

    def forward(self, x, hidden, cell):
        for conv in (self.conv1, self.conv2, self.conv3, self.conv4):
            x = selu(conv(x))
        hidden, cell = self.lstm(x.view(-1, 32 * 3 * 3), (hidden, cell))
        return self.actor_linear(hidden), hidden, cell


def loaded(module: nn.Module, vector: np.ndarray) -> nn.Module:
    nn.utils.vector_to_parameters(torch.from_numpy(vector.copy()), module.parameters())
    return module


# --- the networks ----------------------------------------------------------------------------------


def test_parameter_counts_are_pytorch_es():
    assert SmallNetPolicy(CARTPOLE).num_params == 4_610
    assert ConvLSTMPolicy(PONG_FRAMES).num_params == 588_710
    assert [part.shape for part in ConvLSTMPolicy(PONG_FRAMES).layout.parts.values()] == \
        [tuple(p.shape) for p in TorchConvLSTM(1, 6).parameters()]


def test_small_net_is_the_torch_module():
    policy = SmallNetPolicy(CARTPOLE)
    vector = policy.initial_params(np.random.default_rng(1))
    module = loaded(TorchSmallNet(4, 2), vector)
    assert list(policy.layout.parts) == list(module.state_dict())
    state = policy.reset(vector)
    for obs in np.random.default_rng(2).normal(0, 2, size=(5, 4)).astype(np.float32):
        with torch.no_grad():
            expected = module(torch.from_numpy(obs)).numpy()
        output, state = policy.act(vector, state, obs)
        np.testing.assert_allclose(output, expected, rtol=1e-5, atol=1e-6)
    assert np.abs(output).max() > 0


def test_default_initialisation_bounds():
    """PyTorch's defaults: U(+-1/sqrt(fan_in)) for convs and linears, U(+-1/16) for the LSTM cell."""
    policy = ConvLSTMPolicy(PONG_FRAMES)
    vector = policy.initial_params(np.random.default_rng(3))
    bounds = {"conv1.weight": 1 / 3, "conv2.bias": 1 / math.sqrt(288), "lstm.weight_hh": 1 / 16,
              "lstm.bias_ih": 1 / 16, "actor_linear.weight": 1 / 16}
    for name, bound in bounds.items():
        values = policy.layout.view(vector, name)
        assert np.abs(values).max() <= bound and np.abs(values).max() > 0.9 * bound, name


def test_conv_lstm_carries_its_state_and_resets_it():
    policy = ConvLSTMPolicy(PONG_FRAMES)
    vector = policy.initial_params(np.random.default_rng(4))
    module = loaded(TorchConvLSTM(1, 6), vector)
    frames = np.random.default_rng(5).normal(size=(4, 1, 42, 42)).astype(np.float32)

    def torch_episode():
        hidden, cell, outputs = torch.zeros(1, 256), torch.zeros(1, 256), []
        with torch.no_grad():
            for frame in frames:
                logits, hidden, cell = module(torch.from_numpy(frame)[None], hidden, cell)
                outputs.append(logits.numpy()[0])
        return outputs

    def policy_episode():
        state, outputs = policy.reset(vector), []
        for frame in frames:
            output, state = policy.act(vector, state, frame)
            outputs.append(output.copy())
        return outputs

    expected, first, second = torch_episode(), policy_episode(), policy_episode()
    np.testing.assert_allclose(first, expected, rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(first, second)  # reset: the second episode starts from zeros again
    assert not np.allclose(first[0], first[-1], atol=1e-4)  # the state moved: same net, other outputs
    # The hidden state is what carries it: the last frame alone, from a zero state, acts otherwise.
    alone = policy.act(vector, policy.reset(vector), frames[-1])[0]
    assert not np.allclose(alone, first[-1], atol=1e-4)


@pytest.mark.parametrize("policy, net, words", [
    (ConvLSTMPolicy, CARTPOLE, "--network lstm is pytorch-es's conv-LSTM for images"),
    (SmallNetPolicy, NetworkSpec((4, 84, 84), 6), "--network small is pytorch-es's MLP for state vectors")])
def test_networks_refuse_the_wrong_observations(policy, net, words):
    with pytest.raises(ValueError, match=words) as error:
        policy(net)
    assert "\n" not in str(error.value)


def test_default_cnn_takes_the_frame_stack():
    """conv1 takes the observation's channels: (6, 4, 3, 3) on a stack of 4 frames."""
    policy = StaticPolicy(NetworkSpec((4, 84, 84), 6))
    assert policy.layout["conv1"].shape == (6, 4, 3, 3)
    assert policy.num_params == 6 * 4 * 9 + 1200 + 648 * 128 + 128 * 64 + 64 * 6
    vector = policy.initial_params(np.random.default_rng(6))
    conv1, conv2 = (torch.from_numpy(policy.layout.view(vector, name).copy()) for name in ("conv1", "conv2"))
    head = [torch.from_numpy(policy.layout.view(vector, name).copy()) for name in ("fc1", "fc2", "fc3")]
    obs = np.random.default_rng(7).uniform(0, 1, (4, 84, 84)).astype(np.float32)
    with torch.no_grad():
        x = torch.from_numpy(obs)[None]
        x = nn.functional.max_pool2d(torch.tanh(nn.functional.conv2d(x, conv1)), 2)
        x = nn.functional.max_pool2d(torch.tanh(nn.functional.conv2d(x, conv2, stride=2)), 2).view(-1)
        expected = head[2] @ torch.tanh(head[1] @ torch.tanh(head[0] @ x))
    np.testing.assert_allclose(policy.act(vector, policy.reset(vector), obs)[0], expected.numpy(), rtol=1e-4,
                               atol=1e-6)


# --- the preprocessing -----------------------------------------------------------------------------


class Screens(gym.Env):
    """Scripted RGB screens (210 x 160 x 3), a new random one at every reset and step."""

    observation_space = spaces.Box(0, 255, (210, 160, 3), dtype=np.uint8)
    action_space = spaces.Discrete(2)

    def __init__(self):
        self.frames = []

    def _frame(self):
        self.frames.append(self.np_random.integers(0, 256, (210, 160, 3), dtype=np.uint8))
        return self.frames[-1]

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self._frame(), {}

    def step(self, action):
        return self._frame(), 0.0, False, False, {}


def process_frame42(frame):
    """pytorch-es's ``_process_frame42`` (docs/original.md, "pytorch-es")."""
    frame = frame[34:34 + 160, :160]
    frame = cv2.resize(cv2.resize(frame, (80, 80)), (42, 42))
    frame = frame.mean(2).astype(np.float32)
    frame *= 1.0 / 255.0
    return np.reshape(frame, [1, 42, 42])


def test_frame42_is_pytorch_es_frame():
    env = PytorchESFrame(Screens(), ATARI_CROP)
    observation, _ = env.reset(seed=1)
    assert observation.shape == (1, 42, 42) and observation.dtype == np.float32
    np.testing.assert_array_equal(observation, process_frame42(env.unwrapped.frames[-1]))


def test_running_normalisation_is_the_spec_and_restarts_every_episode():
    env = RunningNormalisation(PytorchESFrame(Screens(), ATARI_CROP))
    for episode in range(2):
        observations = [env.reset(seed=episode)[0]] + [env.step(0)[0] for _ in range(3)]
        mean = std = 0.0
        for t, frame in enumerate(env.unwrapped.frames[-4:], start=1):
            processed = process_frame42(frame)
            mean = mean * 0.9999 + float(processed.mean()) * (1 - 0.9999)
            std = std * 0.9999 + float(processed.std()) * (1 - 0.9999)
            expected = (processed - np.float32(mean / (1 - 0.9999 ** t))) / np.float32(std / (1 - 0.9999 ** t) + 1e-8)
            np.testing.assert_array_equal(observations[t - 1], expected)
        # the first frame of an episode is its own statistics: mean 0, std 1
        assert abs(observations[0].mean()) < 1e-5 and abs(observations[0].std() - 1) < 1e-4


# --- NES utilities ---------------------------------------------------------------------------------


def pytorch_es_shaping(returns):
    """pytorch-es's ``fitness_shaping`` after PR #8, transcribed (docs/original.md, "pytorch-es")."""
    sorted_returns_backwards = sorted(returns)[::-1]
    lamb = len(returns)
    denom = sum(max(0, math.log(lamb / 2 + 1, 2) - math.log(sorted_returns_backwards.index(r) + 1, 2))
                for r in returns)
    return [max(0, math.log(lamb / 2 + 1, 2) - math.log(sorted_returns_backwards.index(r) + 1, 2)) / denom + 1 / lamb
            for r in returns]


def test_nes_utilities_exact_values():
    # lambda = 4: log2(3) for the best, log2(3) - 1 for the second, 0 for the rest; + 1/4 each
    utilities = nes_utilities(np.array([3.0, 1.0, 2.0, 0.0]))
    best, second = math.log2(3), math.log2(3) - 1
    np.testing.assert_allclose(utilities, [best / (best + second) + 0.25, 0.25, second / (best + second) + 0.25, 0.25],
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(nes_utilities(np.array([0.0, 5.0])), [0.5, 1.5], rtol=0, atol=1e-15)


@pytest.mark.parametrize("returns", [[-21, -20, -21, -19, -21, -18], [5, 5, 1, 7, 5, 0, 3, 3], list(range(40))])
def test_nes_utilities_are_pytorch_es(returns):
    np.testing.assert_allclose(nes_utilities(np.array(returns, dtype=float)), pytorch_es_shaping(returns),
                               rtol=1e-13, atol=0)


def test_nes_utilities_tied_pair_cancels_and_equal_fitness_gives_no_step():
    utilities = nes_utilities(np.array([2.0, 2.0, 1.0, 0.0]))
    assert utilities[0] == utilities[1]
    assert nes_utilities(np.array([-21.0] * 6)) is None


@pytest.mark.parametrize("name, environment, network", [("pong", "PongDeterministic-v4", "lstm"),
                                                        ("cartpole", "CartPole-v1", "small")])
def test_pytorch_es_experiment_files_hold_its_defaults(name, environment, network):
    from cli.config import TrainConfig

    experiments = Path(__file__).resolve().parent.parent / "experiments"
    config = TrainConfig.from_toml(experiments / "pytorch_es" / f"{name}.toml")
    assert (config.env.environment, config.policy.kind, config.policy.network) == (environment, "static", network)
    es = config.es
    assert (es.popsize, es.lr, es.decay, es.sigma, es.sigma_decay, es.fitness_l2) == (40, 0.1, 1.0, 0.05, 1.0, 0.0)
    assert es.shaping == "nes"
