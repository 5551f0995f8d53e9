"""The outer loop's bookkeeping on optuna: samplers, the journal file, study names, recorded settings.

As in ER-MRL (docs/original.md, "ER-MRL"), a study lives in ``optuna-journal_<name>.log`` in the current
folder and is loaded if it exists, so running an evolve script again adds trials to it, and several
processes, on one machine or on machines sharing the folder, can run trials of one study at once
(the original's SLURM arrays: 90 jobs of 10 trials on one journal). The journal is written through
optuna's ``JournalFileBackend``, whose file format is that of the ``JournalFileStorage`` the original
used (deprecated since optuna 4.0), so the original's journals load here.

A study also records the settings it was created with (units, skip_c, ...): a later process that
would mix other settings into it is refused, and the test scripts rebuild the reservoirs it evolved.

A journal is data someone may hand you, but optuna's CMA-ES sampler keeps its optimiser in it as a
pickle (hex text split over the trial's system attributes ``cma:...:optimizer:0``, ``:1``, ...; optuna
4's ``samplers/_cmaes.py``) and unpickles it when the study continues. So before optuna reads a
journal, every such pickle in it is loaded once through ``SafeUnpickler``, which builds only the
classes the sampler stores there (the ``cmaes`` optimisers, numpy arrays, dtypes and scalars);
a journal holding anything else is refused and left as it was.
"""

from __future__ import annotations

import io
import json
import pickle
import re
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
    a bad last line at first and fails on it in the middle of a trial once it has appended after it.
    Then refuse one whose sampler state is not plain data (``check_pickles``)."""
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
    check_pickles(path)


# (module, name) of every global a genuine CmaEsSampler pickle names: its optimisers (CMA; SepCMA with
# use_separable_cma; CMAwM with_margin) and the numpy pieces of their arrays, under numpy 1's and 2's paths
SAFE_GLOBALS = frozenset({
    ("cmaes._cma", "CMA"), ("cmaes._sepcma", "SepCMA"), ("cmaes._cmawm", "CMAwM"),
    ("numpy", "ndarray"), ("numpy", "dtype"),
    *((module, name) for module in ("numpy.core.multiarray", "numpy._core.multiarray")
      for name in ("_reconstruct", "scalar")),
    *(("builtins", name) for name in ("complex", "frozenset", "set", "slice", "range", "bytearray")),
})
OPTIMIZER_KEY = re.compile(r"(cma|sepcma|cmawm):(\w+:restart_\d+:)?optimizer")  # optuna's optimizer_key_template


class UnsafeJournal(ValueError):
    """A journal whose pickled sampler state names a class outside SAFE_GLOBALS."""


class SafeUnpickler(pickle.Unpickler):
    """Builds only the globals in SAFE_GLOBALS; any other is refused before it is imported."""

    def find_class(self, module: str, name: str):
        if (module, name) not in SAFE_GLOBALS:
            raise UnsafeJournal(f"{module}.{name}")
        return super().find_class(module, name)


def safe_loads(data: bytes):
    return SafeUnpickler(io.BytesIO(data)).load()


def optimizer_pickles(system_attrs: dict) -> dict[str, str | None]:
    """The pickles optuna's CmaEsSampler would unpickle from a trial's system attributes, as it joins them
    (the keys starting with an optimizer key, values ``<key>:0`` .. ``<key>:<n-1>`` in order): key -> hex
    text, or None where the parts do not join."""
    found = {}
    for base in {match.group(0) for key in system_attrs if (match := OPTIMIZER_KEY.match(str(key)))}:
        count = sum(1 for key in system_attrs if str(key).startswith(base))
        parts = [system_attrs.get(f"{base}:{index}") for index in range(count)]
        found[base] = "".join(parts) if all(isinstance(part, str) for part in parts) else None
    return found


def check_pickles(path: Path) -> None:
    """Load every pickle optuna could unpickle from the journal through SafeUnpickler; refuse the journal
    if one names another class or does not decode (for a trial still running, another process may be
    writing its parts: only a forbidden class counts there)."""
    storage = open_journal(path)
    try:
        trials = [trial for study in storage.get_all_studies() for trial in storage.get_all_trials(study._study_id)]
    except Exception as error:  # a line optuna cannot replay
        raise ValueError(f"the journal {path} is corrupt ({type(error).__name__}: {error}); move it away, or give "
                         "another --h_test") from None
    for trial in trials:
        finished = trial.state.is_finished()
        for key, text in optimizer_pickles(trial.system_attrs).items():
            try:
                if text is None:
                    raise ValueError("its parts do not join")
                optimizer = safe_loads(bytes.fromhex(text))
                if not any(isinstance(optimizer, cls) for cls in _optimizer_classes()):
                    raise ValueError(f"it holds a {type(optimizer).__name__}, not a CMA-ES optimiser")
            except UnsafeJournal as error:
                raise UnsafeJournal(f"refused the journal {path}: trial {trial.number}'s {key} is a pickle that "
                                    f"asks for {error}, which is not CMA-ES sampler state and could run code; "
                                    "it was left as it was") from None
            except Exception as error:
                if finished:
                    raise ValueError(f"the journal {path} is corrupt: trial {trial.number}'s {key} is not CMA-ES "
                                     f"sampler state ({type(error).__name__}: {error})") from None


def _optimizer_classes() -> tuple[type, ...]:
    import cmaes

    return cmaes.CMA, cmaes.SepCMA, cmaes.CMAwM


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
