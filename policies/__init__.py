"""Policies: static and Hebbian networks behind one protocol (EvoJAX style).

Every policy has ``num_params``, a named ``layout`` of its flat float32 parameter vector, the slice
``penalised`` by the ES's L2 term, ``initial_params(rng, distribution)``,
``reset(params, rng) -> state`` and ``act(params, state, obs) -> (output, state)``, plus
``export``/``load`` to and from the original file shapes. Policies know arrays, never environments.
"""

from policies.hebbian import DISTRIBUTIONS, HebbianPolicy
from policies.init import INIT_CHOICES
from policies.network import NetworkSpec
from policies.rules import RULES
from policies.static import StaticPolicy

__all__ = ["DISTRIBUTIONS", "INIT_CHOICES", "RULES", "HebbianPolicy", "NetworkSpec", "StaticPolicy"]
