"""Short Pong for tests: the three Pong ids this project supports, each capped at ``FRAMES`` emulator
frames (ale-py's ``max_num_frames_per_episode``), so that an episode is 100 agent steps, not ~800.

``--environment tests.atari_short:ShortPong-v5`` imports this module, which registers the ids as
copies of ale-py's (and of ``envs.atari``'s ``PongDeterministic-v4``) with that cap; the environment
is ale-py's own ``AtariEnv``, so the Atari recipe applies as to the real ids.
"""

from __future__ import annotations

import gymnasium as gym

import envs  # noqa: F401  (registers ale-py's ids and the Deterministic ones)

FRAMES = 400
ORIGINALS = {"ShortPongNoFrameskip-v4": "PongNoFrameskip-v4", "ShortPongDeterministic-v4": "PongDeterministic-v4",
             "ShortPong-v5": "ALE/Pong-v5"}

for short, original in ORIGINALS.items():
    if short not in gym.registry:
        spec = gym.spec(original)
        gym.register(short, entry_point=spec.entry_point,
                     kwargs={**spec.kwargs, "max_num_frames_per_episode": FRAMES})
