"""The outer loop's bookkeeping on optuna: samplers, the journal file, study names, recorded settings.

As in ER-MRL (upstream spec §8.2), a study lives in ``optuna-journal_<name>.log`` in the current
folder and is loaded if it exists, so running an evolve script again adds trials to it, and several
processes, on one machine or on machines sharing the folder, can run trials of one study at once
(the original's SLURM arrays: 90 jobs of 10 trials on one journal). The journal is written through
optuna's ``JournalFileBackend``, whose file format is that of the ``JournalFileStorage`` the original
used (deprecated since optuna 4.0), so the original's journals load here.

A study also records the settings it was created with (units, skip_c, ...): a later process that
would mix other settings into it is refused, and the test scripts rebuild the reservoirs it evolved.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import optuna
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend

SAMPLERS = ("Random", "Tpe", "Cmaes")
SETTINGS_ATTR = "er_mrl_settings"
JOURNAL_PREFIX = "optuna-journal_"


def study_name(*parts: object, training_steps: int) -> str:
    """The original's names: ``{env_id}_{h_test}_{k}k_steps`` (evolve_res), ``{env_id}_{nb_res}_{h_test}_{k}k_steps``
    (evolve_multi_res), ``{env_type}_{nb_res}_{h_test}_{k}k_steps`` (evolve_generalization)."""
    return "_".join(str(part) for part in parts) + f"_{training_steps // 1000}k_steps"


def journal_path(name: str) -> Path:
    return Path(f"{JOURNAL_PREFIX}{safe_file_name(name)}.log")


def safe_file_name(text: str) -> str:
    """``text`` usable as one file or folder name (a namespaced id such as ALE/Pong-v5 has a slash)."""
    return text.replace("/", "_")


def make_sampler(name: str, seed: int | None) -> optuna.samplers.BaseSampler:
    """The original's ``generate_sampler``, seeded. CMA-ES restarts with a doubled population (IPOP)."""
    if name == "Random":
        return optuna.samplers.RandomSampler(seed=seed)
    if name == "Tpe":
        return optuna.samplers.TPESampler(seed=seed)
    if name == "Cmaes":
        with warnings.catch_warnings():  # restart_strategy is marked experimental
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            return optuna.samplers.CmaEsSampler(restart_strategy="ipop", seed=seed)
    raise ValueError(f"unknown sampler {name!r}; valid: {', '.join(SAMPLERS)}")


def process_seed(sampler_seed: int | None, trials_before: int) -> int | None:
    """The sampler's seed for a process that finds ``trials_before`` trials in the study.

    Mixing in the count makes a resumed run draw new points instead of repeating the first ones,
    while the same commands in the same order still draw the same points.
    """
    if sampler_seed is None:
        return None
    return int(np.random.SeedSequence([sampler_seed, trials_before]).generate_state(1)[0])


def open_journal(path: Path) -> JournalStorage:
    return JournalStorage(JournalFileBackend(str(path)))


def check_journal(path: Path) -> None:
    """Refuse a journal with a line that is not JSON, before optuna reads or appends to it: optuna skips
    a bad last line at first and fails on it in the middle of a trial once it has appended after it."""
    if not path.is_file():
        return
    with open(path, "rb") as handle:
        for number, line in enumerate(handle, 1):
            if not line.endswith(b"\n"):  # another process's write in progress, as optuna reads it
                break
            try:
                json.loads(line)
            except ValueError:
                raise ValueError(f"the journal {path} is corrupt (line {number} is not JSON); move it away, or give "
                                 "another --h_test") from None


def open_study(name: str, settings: dict, sampler: str, sampler_seed: int | None) -> optuna.Study:
    """Create the study, or load it if its journal has it; refuse settings that differ from its own."""
    path = journal_path(name)
    check_journal(path)
    storage = open_journal(path)
    try:  # loading first writes nothing, so a refused command leaves the journal as it was
        study = optuna.load_study(study_name=name, storage=storage)
    except KeyError:
        if path.is_file() and path.stat().st_size:  # a journal of this name holds this study, or is not one
            raise ValueError(f"{path} holds no readable study {name!r} (is it corrupt?); move it away, or give "
                             "another --h_test") from None
        study = optuna.create_study(study_name=name, storage=storage, direction="maximize", load_if_exists=True)
    recorded = study.user_attrs.get(SETTINGS_ATTR)
    if recorded is None:
        study.set_user_attr(SETTINGS_ATTR, settings)
    else:
        different = [f"{key} {recorded[key]} (this command: {settings[key]})" for key in settings
                     if key in recorded and recorded[key] != settings[key]]
        if different:
            raise ValueError(f"study {name} was evolved with other settings: {'; '.join(different)}; give the "
                             "same flags to continue it, or another --h_test for a new study")
    study.sampler = make_sampler(sampler, process_seed(sampler_seed, len(study.trials)))
    return study


def load_evolved(name: str, evolve_hint: str) -> optuna.Study:
    """A study with at least one finished trial, for the test scripts; never creates a journal."""
    path = journal_path(name)
    if not path.is_file():
        raise ValueError(f"no journal {path} in {Path.cwd()}; evolve it first: {evolve_hint}")
    check_journal(path)
    try:
        study = optuna.load_study(study_name=name, storage=open_journal(path))
    except KeyError:
        names = [summary.study_name for summary in optuna.get_all_study_summaries(open_journal(path))]
        raise ValueError(f"{path} holds no study {name!r} (it holds {', '.join(names) or 'none'})") from None
    if not any(trial.state == optuna.trial.TrialState.COMPLETE for trial in study.trials):
        raise ValueError(f"study {name} in {path} has no finished trial yet ({len(study.trials)} started, pruned "
                         "or failed); run more trials first")
    return study


def recorded_settings(study: optuna.Study) -> dict:
    """The settings the study was created with; empty for a journal written by the original code."""
    return dict(study.user_attrs.get(SETTINGS_ATTR, {}))
