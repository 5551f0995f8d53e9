"""Evolved reservoirs for meta-reinforcement learning (ER-MRL; Léger, Hamon, Nisioti, Hinaut and
Moulin-Frier, EvoApplications 2024, arXiv 2312.06695), on maintained libraries.

An outer loop (optuna) evolves the hyperparameters of random recurrent networks, reservoirs; an inner
loop trains a PPO agent (stable-baselines3) from scratch on the reservoir's state instead of the
observation. docs/original.md ("ER-MRL") describes the original; docs/reservoirs.md
says what changed.

    esn.py          the echo state network: reservoirpy 0.4 with reservoirpy 0.3's semantics (reset / step
                    on one input); its random draws, which policies.reservoir rescales per member
    wrappers.py     the Gymnasium wrappers of the original, one concern each
    experiments.py  search space, environment presets, target and random returns, the normalised score
    training.py     the inner loop: PPO with SB3's defaults, and a trial's fitness
    study.py        optuna: samplers, journal storage, study names, recorded settings
    commands.py     the six scripts of scripts/, and their one-line errors
    launch.py       what scripts/ run: the optional extra checked, then commands.py

The package itself imports nothing. The optional extra's packages, its install hint and ER-MRL's search
bounds live in the leaf module ``reservoir_extra`` (top level), which the ES front end
(``policies.reservoir``) reads too.
"""
