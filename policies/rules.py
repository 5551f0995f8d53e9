"""The nine synapse-specific Hebbian rules of Najarro & Risi (2020), as one table.

Each rule is a choice of which terms of the general form

    dw_ij = eta * (A * o_i * o_j + B * o_i + C * o_j + D_in) + D_out

it evolves, and in which column of the per-synapse coefficient row each term lives (docs/original.md,
"Hebbian rules"). Terms a rule does not evolve are 0, and eta is 1. ``o_i`` is the pre-synaptic activity, ``o_j``
the post-synaptic one. The column order is the original's, so coefficient files written by the
original code load unchanged:

    rule                   columns                     dw_ij
    A                      A                           A o_i o_j
    AD                     A D                         A o_i o_j + D
    AD_lr                  A D eta                     eta (A o_i o_j + D)
    ABC                    A B C                       A o_i o_j + B o_i + C o_j
    ABC_lr                 A B C eta                   eta (A o_i o_j + B o_i + C o_j)
    ABCD                   A B C D                     A o_i o_j + B o_i + C o_j + D
    ABCD_lr                A B C eta D_in              eta (A o_i o_j + B o_i + C o_j + D_in)
    ABCD_lr_D_out          A B C eta D_out             eta (A o_i o_j + B o_i + C o_j) + D_out
    ABCD_lr_D_in_and_out   A B C eta D_in D_out        eta (A o_i o_j + B o_i + C o_j + D_in) + D_out

``ABCD_lr`` is the paper's model and the default.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TERMS = ("A", "B", "C", "eta", "D_in", "D_out")
_ABSENT = {"A": 0.0, "B": 0.0, "C": 0.0, "eta": 1.0, "D_in": 0.0, "D_out": 0.0}


@dataclass(frozen=True)
class Rule:
    """A Hebbian rule: the term held in each column of a synapse's coefficient row."""

    name: str
    columns: tuple[str, ...]

    @property
    def n_coeffs(self) -> int:
        return len(self.columns)

    def terms(self, coeffs: np.ndarray) -> dict[str, np.ndarray | float]:
        """Split coefficients (..., n_coeffs) into the six terms; absent terms are scalars."""
        named = {name: coeffs[..., column] for column, name in enumerate(self.columns)}
        return {name: named.get(name, _ABSENT[name]) for name in TERMS}

    def fold(self, coeffs: np.ndarray) -> np.ndarray:
        """The four per-synapse factors (a, b, c, d) of  dw = (a o_j + b) o_i + c o_j + d.

        ``coeffs`` is (..., n_coeffs); the result is (4, ...) float32, what the compiled kernel reads.
        """
        t = self.terms(coeffs)
        shape = coeffs.shape[:-1]
        folded = np.empty((4,) + shape, dtype=np.float32)
        folded[0] = t["eta"] * t["A"]
        folded[1] = t["eta"] * t["B"]
        folded[2] = t["eta"] * t["C"]
        folded[3] = t["eta"] * t["D_in"] + t["D_out"]
        return folded


RULES: dict[str, Rule] = {
    rule.name: rule
    for rule in (
        Rule("A", ("A",)),
        Rule("AD", ("A", "D_out")),
        Rule("AD_lr", ("A", "D_in", "eta")),
        Rule("ABC", ("A", "B", "C")),
        Rule("ABC_lr", ("A", "B", "C", "eta")),
        Rule("ABCD", ("A", "B", "C", "D_out")),
        Rule("ABCD_lr", ("A", "B", "C", "eta", "D_in")),
        Rule("ABCD_lr_D_out", ("A", "B", "C", "eta", "D_out")),
        Rule("ABCD_lr_D_in_and_out", ("A", "B", "C", "eta", "D_in", "D_out")),
    )
}


def get_rule(name: str) -> Rule:
    if name not in RULES:
        raise ValueError(f"unknown Hebbian rule {name!r}; valid rules: {', '.join(RULES)}")
    return RULES[name]
