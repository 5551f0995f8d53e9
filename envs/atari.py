"""Atari (ale-py): the ids, the family's frame handling and the original's FIRE reset.

ale-py is optional (``pip install -r requirements-atari.txt``); its wheel ships the ROMs. Importing
it registers ``PongNoFrameskip-v4``, ``ALE/Pong-v5`` and the like. The ``*Deterministic-v0/v4`` ids
of gym 0.17 (pytorch-es's default was ``PongDeterministic-v4``) are gone from ale-py, so they are
registered here as gym 0.17 defined them: a fixed frame skip of 4 (3 for SpaceInvaders),
``repeat_action_probability`` 0 (v4) or 0.25 (v0), on top of ale-py's ``NoFrameskip`` entry of the
same game (its episode cap of 108 000 frames included).

The family's pipeline (``atari_pipeline``), innermost first:

- Gymnasium's ``AtariPreprocessing``: 1-30 no-op steps after each reset (drawn from the
  environment's seeded generator) and a frame skip of 4 with the last two frames max-pooled. Ids
  whose environment already skips frames (``Deterministic``: 4; ``ALE/...-v5``: 4; plain ``-v4``: 2-4
  at random) get ``frame_skip=1`` instead, so frames are never skipped twice: an agent step is
  always the id's own skip, or 4 frames for ``NoFrameskip`` ids.
- ``FireReset`` (the original's ``FireEpisodicLifeEnv``, docs/original.md, "Episodes"), for games whose action
  meanings include FIRE.
- the observation the network expects: 84 x 84 grayscale in [0, 1] stacked over the last 4 steps
  (``FrameStackObservation``), shape (4, 84, 84), for the static CNN and the Hebbian network; or
  pytorch-es's cropped, running-normalised 1 x 42 x 42 frame (``envs.pytorch_es``) for its conv-LSTM.
"""

from __future__ import annotations

import re
import sys

import gymnasium as gym
from gymnasium.envs.registration import parse_env_id
from gymnasium.wrappers import AtariPreprocessing, FrameStackObservation

from envs.pytorch_es import ATARI_CROP, pytorch_es_frames

INSTALL_HINT = "Atari environments need ale-py: pip install -r requirements-atari.txt (or pip install -e '.[atari]')"
FRAME_SKIP = 4
NOOP_MAX = 30
STACK = 4
SCREEN = 84

try:
    import ale_py  # noqa: F401  (registers the ALE ids with Gymnasium)

    AVAILABLE = True
except ImportError:
    AVAILABLE = False

# gym 0.17's Atari games (its ``atari-py`` list), as id names; to recognise an Atari id without ale-py.
_GAMES = ("Adventure AirRaid Alien Amidar Assault Asterix Asteroids Atlantis BankHeist BattleZone BeamRider Berzerk "
          "Bowling Boxing Breakout Carnival Centipede ChopperCommand CrazyClimber Defender DemonAttack DoubleDunk "
          "ElevatorAction Enduro FishingDerby Freeway Frostbite Gopher Gravitar Hero IceHockey Jamesbond "
          "JourneyEscape Kangaroo Krull KungFuMaster MontezumaRevenge MsPacman NameThisGame Phoenix Pitfall Pong "
          "Pooyan PrivateEye Qbert Riverraid RoadRunner Robotank Seaquest Skiing Solaris SpaceInvaders StarGunner "
          "Tennis TimePilot Tutankham UpNDown Venture VideoPinball WizardOfWor YarsRevenge Zaxxon").split()
_LEGACY_NAME = re.compile(r"^(?P<game>[A-Za-z]+?)(-ram)?(NoFrameskip|Deterministic)?$")


def looks_like_atari(env_id: str) -> bool:
    """An id in ale-py's namespace, or one of gym 0.17's Atari names (``Pong-v4``, ``BreakoutNoFrameskip-v4``)."""
    try:
        namespace, name, _ = parse_env_id(env_id.rpartition(":")[2])
    except gym.error.Error:
        return False
    match = _LEGACY_NAME.match(name or "")
    return namespace == "ALE" or (namespace is None and match is not None and match["game"] in _GAMES)


def register_deterministic_ids() -> None:
    """``{Game}Deterministic-v0/v4`` for every ``{Game}NoFrameskip-v0/v4`` ale-py registers (gym 0.17's ids)."""
    for spec in list(gym.registry.values()):
        if spec.namespace is None and spec.name.endswith("NoFrameskip") and str(spec.entry_point).startswith("ale_py"):
            game = spec.name[:-len("NoFrameskip")]
            skip = 3 if game == "SpaceInvaders" else FRAME_SKIP
            env_id = f"{game}Deterministic-v{spec.version}"
            if env_id not in gym.registry:
                gym.register(env_id, entry_point=spec.entry_point, kwargs={**spec.kwargs, "frameskip": skip},
                             max_episode_steps=spec.max_episode_steps)


if AVAILABLE:
    register_deterministic_ids()


def is_atari(env: gym.Env) -> bool:
    if "ale_py" not in sys.modules:  # ale-py absent: no Atari environment can have been made
        return False
    from ale_py.env import AtariEnv

    return isinstance(env, AtariEnv)


class FireReset(gym.Wrapper):
    """Press FIRE, then action 2, after every reset and after every lost life (the original's
    ``FireEpisodicLifeEnv``, docs/original.md, "Episodes"): games such as Breakout stand still until FIRE.

    As in the original, a lost life does not end the episode, the presses' rewards are dropped and
    the observation returned is the one after the second press; a press that ends the game is
    reported as the step's end (a press that ends it during reset resets again).
    """

    def __init__(self, env: gym.Env):
        meanings = env.unwrapped.get_action_meanings()
        if "FIRE" not in meanings or len(meanings) < 3:
            raise ValueError(f"FireReset needs a FIRE action and at least 3 actions, got {meanings}")
        super().__init__(env)
        self._presses = (meanings.index("FIRE"), 2)
        self._lives = 0

    def _press(self):
        observation, terminated, truncated, info = None, False, False, {}
        for action in self._presses:
            observation, _, terminated, truncated, info = self.env.step(action)
            if terminated or truncated:
                break
        return observation, terminated, truncated, info

    def reset(self, **kwargs):
        self.env.reset(**kwargs)
        observation, terminated, truncated, info = self._press()
        if terminated or truncated:
            observation, info = self.env.reset(**kwargs)
        self._lives = info.get("lives", 0)
        return observation, info

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        lives = info.get("lives", 0)
        if self._lives > lives > 0 and not (terminated or truncated):
            observation, terminated, truncated, info = self._press()
            lives = info.get("lives", lives)
        self._lives = lives
        return observation, reward, terminated, truncated, info


def needs_fire(env: gym.Env) -> bool:
    return "FIRE" in env.unwrapped.get_action_meanings()


def atari_pipeline(env: gym.Env, preprocessing: str) -> gym.Env:
    """No-op starts and frame skip, the FIRE reset where the game has FIRE, then the network's images:
    ``default``: (4, 84, 84) grayscale stack in [0, 1]; ``pytorch-es``: (1, 42, 42), normalised."""
    skip = FRAME_SKIP if getattr(env.unwrapped, "_frameskip", None) == 1 else 1  # the id skips frames itself
    if preprocessing == "default":
        env = AtariPreprocessing(env, noop_max=NOOP_MAX, frame_skip=skip, screen_size=SCREEN, scale_obs=True)
    else:  # full-size RGB frames for pytorch-es's own crop and resize
        height, width = env.observation_space.shape[:2]
        env = AtariPreprocessing(env, noop_max=NOOP_MAX, frame_skip=skip, screen_size=(width, height),
                                 grayscale_obs=False)
    if needs_fire(env):
        env = FireReset(env)
    if preprocessing == "default":
        return FrameStackObservation(env, STACK)
    return pytorch_es_frames(env, ATARI_CROP)
