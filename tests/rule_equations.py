"""The nine Hebbian rules of Najarro & Risi (2020), written out from the table of docs/original.md,
"Hebbian rules".

Shared by the rule and policy tests as the reference the fast code is checked against.
"""

# Delta w_ij of each rule; h is the synapse's coefficient row (or, vectorised, a layer's columns).
EQUATIONS = {
    "A": lambda h, o_i, o_j: h[0] * o_i * o_j,
    "AD": lambda h, o_i, o_j: h[0] * o_i * o_j + h[1],
    "AD_lr": lambda h, o_i, o_j: h[2] * (h[0] * o_i * o_j + h[1]),
    "ABC": lambda h, o_i, o_j: h[0] * o_i * o_j + h[1] * o_i + h[2] * o_j,
    "ABC_lr": lambda h, o_i, o_j: h[3] * (h[0] * o_i * o_j + h[1] * o_i + h[2] * o_j),
    "ABCD": lambda h, o_i, o_j: h[3] + h[0] * o_i * o_j + h[1] * o_i + h[2] * o_j,
    "ABCD_lr": lambda h, o_i, o_j: h[3] * (h[0] * o_i * o_j + h[1] * o_i + h[2] * o_j + h[4]),
    "ABCD_lr_D_out": lambda h, o_i, o_j: h[3] * (h[0] * o_i * o_j + h[1] * o_i + h[2] * o_j) + h[4],
    "ABCD_lr_D_in_and_out": lambda h, o_i, o_j: h[3] * (h[0] * o_i * o_j + h[1] * o_i + h[2] * o_j + h[4]) + h[5],
}
