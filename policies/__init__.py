"""Policies: networks behind one protocol (``policies.base.Policy``, EvoJAX style) and a registry of
kinds (``policies.registry``): static networks, whose weights are evolved (the original's, or
pytorch-es's small net and conv-LSTM), and Hebbian networks, whose plasticity rules are. Policies know
arrays, never environments.
"""

from policies.base import Policy
from policies.hebbian import DISTRIBUTIONS, HebbianPolicy
from policies.init import INIT_CHOICES
from policies.network import NetworkSpec
from policies.registry import KINDS, NETWORKS, PolicySettings, kind_of, make_policy, preprocessing
from policies.rules import RULES
from policies.static import StaticPolicy

__all__ = ["DISTRIBUTIONS", "INIT_CHOICES", "KINDS", "NETWORKS", "RULES", "HebbianPolicy", "NetworkSpec", "Policy",
           "PolicySettings", "StaticPolicy", "kind_of", "make_policy", "preprocessing"]
