"""What a user is handed stays data, and what a run does stays its own, shown working:

- a genuine CMA-ES journal passes the allowlist and continues exactly as optuna alone continues it,
  and the allowlisted unpickler rebuilds the very optimiser that ``pickle`` does;
- module names recorded in a run's settings: plain non-standard-library names only;
- a run folder's lock keeps a second holder out, and a failed start leaves no folder;
- outputs: the guard's rules, and every writer writes the format its suffix names;
- TensorBoard after a resume has each generation once;
- SIGINT stops a process started with SIGINT ignored (a background job of a script); a closed pipe
  ends training quietly.

The bad inputs themselves, through the scripts, are in ``test_bad_inputs.py``.
"""

from __future__ import annotations

import os
import pickle
import shlex
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from envs.modules import UnsafeModule, recorded_modules, resume_imports
from es.files import read_metrics
from es.outputs import OutputRefused, check_output
from es.runfolder import RunFolder, RunFolderError
from tests.test_bad_inputs import BASE_ENV, EVOLVE, EXTRA_REASON, ROOT, STUDY, genuine_journal, has_extra

# --- journals -------------------------------------------------------------------------------------


def continue_study(folder: Path, checked: bool, trials: int) -> list[tuple[int, dict, float]]:
    """``trials`` more trials of the journal in ``folder``: through the project's open_study (checked), or
    through optuna alone with the same sampler and seed; every trial's number, parameters and value."""
    import optuna

    from reservoirs.commands import evolve_res_parser, search_settings, search_space
    from reservoirs.study import journal_path, make_sampler, open_journal, open_study, process_seed

    args = evolve_res_parser("evolve_res.py").parse_args([*EVOLVE, "--nb_trials", "1"])
    space = search_space(args, 1, suffixed=False)
    previous = Path.cwd()
    os.chdir(folder)
    try:
        if checked:
            study = open_study(STUDY, search_settings(args, space, env=args.env_id, del_obs=args.del_obs), "Cmaes", 3)
        else:
            study = optuna.load_study(study_name=STUDY, storage=open_journal(journal_path(STUDY)))
            study.sampler = make_sampler("Cmaes", process_seed(3, len(study.trials)))
        study.optimize(lambda trial: -abs(np.log(space.sample(trial)[0].spectral_radius)), n_trials=trials)
        return [(trial.number, trial.params, trial.value) for trial in study.trials]
    finally:
        os.chdir(previous)


@pytest.mark.skipif(not has_extra(), reason=EXTRA_REASON)
def test_a_genuine_cmaes_journal_continues_bit_for_bit(tmp_path):
    (tmp_path / "made").mkdir()
    journal = genuine_journal(tmp_path / "made", trials=9)
    copies = []
    for name in ("checked", "optuna"):
        (tmp_path / name).mkdir()
        copies.append(tmp_path / name)
        shutil.copy(journal, tmp_path / name / journal.name)
    checked = continue_study(copies[0], checked=True, trials=8)  # past the next generation of 6: the optimiser is read
    alone = continue_study(copies[1], checked=False, trials=8)
    assert len(checked) == 17 and checked == alone
    assert (copies[0] / journal.name).read_bytes().startswith(journal.read_bytes())


@pytest.mark.skipif(not has_extra(), reason=EXTRA_REASON)
def test_the_allowlist_rebuilds_the_optimiser_pickle_does(tmp_path):
    from reservoirs.study import open_journal, optimizer_pickles, safe_loads

    journal = genuine_journal(tmp_path, trials=9)
    storage = open_journal(journal)
    study_id = storage.get_all_studies()[0]._study_id
    found = [text for trial in storage.get_all_trials(study_id)
             for text in optimizer_pickles(trial.system_attrs).values()]
    assert found and all(text is not None for text in found)
    for text in found:
        safe, plain = safe_loads(bytes.fromhex(text)).__getstate__(), pickle.loads(bytes.fromhex(text)).__getstate__()
        assert safe.keys() == plain.keys()
        for key in plain:
            assert np.array_equal(np.asarray(safe[key]), np.asarray(plain[key])), key


@pytest.mark.skipif(not has_extra(), reason=EXTRA_REASON)
def test_the_allowlist_refuses_any_other_global():
    from reservoirs.study import UnsafeJournal, safe_loads

    for payload in (pickle.dumps(print), pickle.dumps(os.getcwd), pickle.dumps(np.load), pickle.dumps(Path("."))):
        with pytest.raises(UnsafeJournal):
            safe_loads(payload)
    array = np.arange(6, dtype=np.float32).reshape(2, 3)
    assert np.array_equal(safe_loads(pickle.dumps(array)), array)


# --- recorded modules -----------------------------------------------------------------------------


def test_recorded_modules_are_plain_names_outside_the_standard_library():
    assert recorded_modules(("tests.custom_env_module:TestCorridor-v0", "CartPole-v1"), ("tests.custom_recipe",)) == (
        "tests.custom_env_module", "tests.custom_recipe")
    line = resume_imports(("tests.custom_env_module:TestCorridor-v0",), ("tests.custom_recipe",), "RUN/config.json")
    assert line == "importing tests.custom_env_module, tests.custom_recipe, as RUN/config.json names"
    assert resume_imports(("CartPole-v1",), (), "RUN/config.json") is None
    for name in ("os", "subprocess", "antigravity", "this", "os.path", "sys", "__main__", "../x", "a..b", "x y", "",
                 ".relative", "mod:attr"):
        with pytest.raises(UnsafeModule):
            resume_imports((), (name,), "RUN/config.json")


# --- the lock and a failed start ------------------------------------------------------------------


def test_a_run_folder_has_one_holder(tmp_path):
    first = RunFolder.create(tmp_path / "runs", "CartPole-v1", 1)
    assert (first.path / ".lock").is_file()
    with pytest.raises(RunFolderError, match="in use by another process"):
        RunFolder(first.path).lock()  # another open file description: as another process
    assert (first.path / ".lock").is_file()


def test_a_refused_start_leaves_no_folder_behind(tmp_path):
    threads = str(4 * (os.cpu_count() or 1) + 1)
    result = subprocess.run([sys.executable, str(ROOT / "train_static.py"), "--environment", "CartPole-v1", "--popsize",
                             "4", "--threads", threads, "--folder", str(tmp_path / "a" / "b")],
                            cwd=ROOT, env=BASE_ENV, check=False, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and "worker processes" in result.stderr
    assert list(tmp_path.iterdir()) == []


# --- outputs --------------------------------------------------------------------------------------


def test_the_output_guard(tmp_path):
    run = tmp_path / "run"
    (run / "tensorboard").mkdir(parents=True)
    (run / "config.json").write_text("{}")
    (run / "last.dat").write_bytes(b"x")
    for name in ("config.json", "metrics.csv", "checkpoint.npz", "fitness.png", "tensorboard/a.png", ".lock"):
        with pytest.raises(OutputRefused):
            check_output("--plot", run / name, (".png", ".json", ".csv", ".npz", ""))
    assert check_output("--json", run / "evaluation.json", (".json",)) == run / "evaluation.json"  # a new name
    for name in ("evaluation.json", "adaptation.png", "frames.png"):  # once there, a file of the run like any
        (run / name).write_bytes(b"an earlier evaluation's")
        with pytest.raises(OutputRefused, match=f"is {name} of the run folder {run}, which exists: an output never "
                                                "replaces a run's file"):
            check_output("--plot", run / name, (".png", ".json"))
    assert check_output("--plot", tmp_path / "fitness.png", (".png",)) == tmp_path / "fitness.png"  # not a run's
    (tmp_path / "fitness.png").write_bytes(b"x")  # outside a run folder, a file of the user's to replace
    assert check_output("--plot", tmp_path / "fitness.png", (".png",)) == tmp_path / "fitness.png"
    with pytest.raises(OutputRefused, match="which this command reads"):
        check_output("--json", tmp_path / "in.json", (".json",), [tmp_path / "in.json"])
    with pytest.raises(OutputRefused, match="optuna journal"):
        check_output("--json", tmp_path / "optuna-journal_x.log", (".log",))
    with pytest.raises(OutputRefused, match="ending in .png"):
        check_output("-o", tmp_path / "x.jpg", (".png",))
    with pytest.raises(OutputRefused, match="not an existing writable folder"):
        check_output("-o", tmp_path / "missing" / "x.png", (".png",))
    if Path("/sys/kernel").is_dir():  # no file can be created there, by root either, whatever its permissions say
        with pytest.raises(OutputRefused, match="/sys/kernel is not an existing writable folder"):
            check_output("--video", "/sys/kernel/x.mp4", (".mp4",))
    assert sorted(path.name for path in tmp_path.iterdir()) == ["fitness.png", "run"]  # the probes left nothing


@pytest.mark.parametrize("suffix, head", [(".png", b"\x89PNG"), (".pdf", b"%PDF"), (".svg", b"<?xml")])
def test_a_figure_is_written_in_the_format_its_suffix_names(tmp_path, suffix, head):
    from report.plots import save_comparison

    rows = [{"generation": 1, "fitness_mean": 1.0, "fitness_max": 2.0, "fitness_min": 0.0}]
    save_comparison(tmp_path / f"x{suffix}", [("run", rows)])
    assert (tmp_path / f"x{suffix}").read_bytes().startswith(head)
    assert [path.name for path in tmp_path.iterdir()] == [f"x{suffix}"]  # no temporary file left


# --- TensorBoard ----------------------------------------------------------------------------------


def test_tensorboard_after_a_resume_has_each_generation_once(tmp_path):
    pytest.importorskip("tensorboard", reason="optional: pip install -r requirements-tensorboard.txt")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    def train(*words) -> None:
        result = subprocess.run([sys.executable, str(ROOT / "train_static.py"), *words], cwd=ROOT, env=BASE_ENV,
                                check=False, capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, result.stderr

    train("--environment", "CartPole-v1", "--popsize", "4", "--generations", "2", "--threads", "1", "--seed", "3",
          "--folder", str(tmp_path), "--tensorboard")
    (run,) = [path for path in tmp_path.iterdir() if path.is_dir()]
    kept = {name: (run / name).read_bytes() for name in ("checkpoint.npz", "metrics.csv")}
    train("--resume", str(run), "--generations", "3")
    for name, data in kept.items():  # as if the process had been killed after generation 3's events, before its save
        (run / name).write_bytes(data)
    train("--resume", str(run), "--generations", "4")
    events = EventAccumulator(str(run / "tensorboard"))
    events.Reload()
    points = [(event.step, event.value) for event in events.Scalars("fitness_mean")]
    rows = read_metrics(run / "metrics.csv")
    assert [step for step, _ in points] == [1, 2, 3, 4]
    assert np.allclose([value for _, value in points], [float(row["fitness_mean"]) for row in rows])


# --- signals and pipes ----------------------------------------------------------------------------


def test_sigint_stops_a_process_started_with_sigint_ignored(run_folder):
    command = shlex.join([sys.executable, str(ROOT / "evaluate_static.py"), "--environment", "CartPole-v1",
                          "--path_weights", str(run_folder / "last.dat"), "--episodes", "100000"])
    process = subprocess.Popen(["bash", "-c", f"trap '' INT; exec {command}"], cwd=ROOT, env=BASE_ENV,  # as `cmd &`
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # in a script: INT ignored
    try:
        for line in process.stdout:
            if "| episode 1 |" in line:
                break
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=60) == 130
        assert "interrupted; the episodes done" in process.stdout.read()
    finally:
        process.kill()
        process.wait()


def test_a_closed_pipe_ends_training_quietly(tmp_path):
    command = (f"{sys.executable} train_static.py --environment CartPole-v1 --popsize 4 --generations 3 --threads 1 "
               f"--folder {tmp_path} 2>{tmp_path / 'err'} | head -1; echo ${{PIPESTATUS[0]}}")
    result = subprocess.run(["bash", "-c", command], cwd=ROOT, env=BASE_ENV, check=False, capture_output=True,
                            text=True, timeout=300)
    assert result.stdout.splitlines()[-1] == "0"
    assert (tmp_path / "err").read_text() == ""


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory) -> Path:
    from tests.test_bad_inputs import trained_run

    return trained_run(tmp_path_factory.mktemp("trust_run"))
