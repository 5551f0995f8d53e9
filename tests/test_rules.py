"""The nine Hebbian rules (policies/rules.py) against the equations of docs/original.md, "Hebbian rules".

Each rule's folded form (a o_j + b) o_i + c o_j + d, the factors the compiled Hebbian kernel reads
(``Rule.fold``), is compared with a plain per-synapse loop that reads coefficient row
``offset + i * n_out + j`` (i pre-synaptic,
j post-synaptic) with the column meanings of the original kernels: 0 = A, 1 = B, 2 = C, 3 = eta
(D in plain ABCD), 4 = D inside eta (D outside for _D_out), 5 = D outside eta.
"""

import numpy as np
import pytest

from policies.rules import RULES, get_rule
from tests.rule_equations import EQUATIONS

N_COEFFS = {"A": 1, "AD": 2, "AD_lr": 3, "ABC": 3, "ABC_lr": 4, "ABCD": 4, "ABCD_lr": 5,
            "ABCD_lr_D_out": 5, "ABCD_lr_D_in_and_out": 6}


def reference_delta(name, rows, offset, pre, post):
    """Per-synapse loop over one layer: W is (n_out, n_in), its synapse (j, i) uses row offset + i*n_out + j."""
    n_in, n_out = pre.size, post.size
    delta = np.zeros((n_out, n_in))
    for i in range(n_in):
        for j in range(n_out):
            delta[j, i] = EQUATIONS[name](rows[offset + i * n_out + j], pre[i], post[j])
    return delta


def layer_coefficients(rows, offset, n_out, n_in):
    """The layer's rows rearranged to (n_out, n_in, k), the weight orientation ``fold`` is given."""
    block = rows[offset:offset + n_in * n_out]  # row-major over (i, j)
    return block.reshape(n_in, n_out, -1).transpose(1, 0, 2)


def test_the_table_holds_exactly_the_nine_rules():
    assert set(RULES) == set(EQUATIONS) == set(N_COEFFS)


@pytest.mark.parametrize("name", list(N_COEFFS))
def test_number_of_coefficients(name):
    assert RULES[name].n_coeffs == N_COEFFS[name]
    assert get_rule(name) is RULES[name]


@pytest.mark.parametrize("name", list(EQUATIONS))
@pytest.mark.parametrize("n_in, n_out", [(5, 3), (3, 7), (1, 1)])
def test_folded_rule_equals_the_per_synapse_loop(name, n_in, n_out):
    rng = np.random.default_rng([sum(map(ord, name)), n_in, n_out])
    k = N_COEFFS[name]
    offset = 4  # the layer is not the first one: its rows start after another layer's
    rows = rng.normal(size=(offset + n_in * n_out + 2, k)).astype(np.float32)
    pre, post = rng.normal(size=n_in), rng.uniform(-1, 1, size=n_out)
    expected = reference_delta(name, rows.astype(np.float64), offset, pre, post)

    a, b, c, d = RULES[name].fold(layer_coefficients(rows, offset, n_out, n_in))
    assert a.shape == (n_out, n_in) and a.dtype == np.float32
    o_i, o_j = pre[None, :], post[:, None]
    folded = (a * o_j + b) * o_i + c * o_j + d

    np.testing.assert_allclose(folded, expected, rtol=1e-5, atol=1e-5)


def test_fold_puts_each_column_in_its_place():
    # eta = 2, A = 3, B = 5, C = 7, D_in = 11, D_out = 13 for the rule that has them all.
    a, b, c, d = RULES["ABCD_lr_D_in_and_out"].fold(np.array([[3.0, 5.0, 7.0, 2.0, 11.0, 13.0]]))
    assert (a[0], b[0], c[0], d[0]) == (6.0, 10.0, 14.0, 35.0)
    # plain ABCD: column 3 is D (no eta), so eta is 1
    a, b, c, d = RULES["ABCD"].fold(np.array([[3.0, 5.0, 7.0, 2.0]]))
    assert (a[0], b[0], c[0], d[0]) == (3.0, 5.0, 7.0, 2.0)
    # AD_lr: columns A, D, eta
    a, b, c, d = RULES["AD_lr"].fold(np.array([[3.0, 5.0, 2.0]]))
    assert (a[0], b[0], c[0], d[0]) == (6.0, 0.0, 0.0, 10.0)


def test_unknown_rule_names_the_valid_ones():
    with pytest.raises(ValueError, match="'ABCDE'") as error:
        get_rule("ABCDE")
    for name in RULES:
        assert name in str(error.value)
