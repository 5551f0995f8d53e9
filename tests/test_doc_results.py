"""The scripts behind the training results of docs/strategies.md, docs/modern-es.md and docs/reservoirs.md
(benchmarks/strategies.py, benchmarks/modern_es.py, experiments/reservoir_front/compare.py --record), with tiny
budgets on real environments: their records hold what the runs' own files and the project's statistics give, and
the same command again trains nothing and writes the same tables."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.extras import need

ROOT = Path(__file__).resolve().parent.parent


def run(script: str, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args], cwd=cwd, capture_output=True,
                          text=True, timeout=600)


def record_of(folder: Path) -> dict:
    [path] = folder.glob("*.json")
    return json.loads(path.read_text())


def run_files(folder: Path) -> dict[Path, int]:
    return {path: path.stat().st_mtime_ns for path in sorted(folder.rglob("*")) if path.is_file()
            and "launch" not in path.name}


def test_strategies_record_is_the_runs_final_scores_and_their_statistics(tmp_path):
    need("stats")
    from report import stats

    args = ["--environment", "CartPole-v1", "--strategies", "openai,pgpe", "--popsize", "4", "--generations", "2",
            "--seeds", "2", "--jobs", "1"]
    first = run("strategies.py", *args, "--results", str(tmp_path / "first"), cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    record = record_of(tmp_path / "first")
    assert record["timed"] is False and record["loaded"] is False
    runs = tmp_path / "runs" / "strategies" / "CartPole-v1"
    assert sorted(path.name for path in runs.iterdir()) == ["hebbian_openai", "hebbian_pgpe", "static_openai",
                                                            "static_pgpe"]
    for kind in ("static", "hebbian"):
        scores = {}
        for strategy in ("openai", "pgpe"):
            found = stats.collect([f"{strategy}={runs / f'{kind}_{strategy}'}"], "final")[strategy]
            scores[strategy] = [found[run] for run in sorted(found, key=lambda run: run.parent.name)]
            assert record["measures"][f"{kind}_{strategy}"]["values"] == scores[strategy]
        table = record["notes"][kind]
        [summary_openai, summary_pgpe] = stats.summarise(scores)
        [pgpe_over_openai] = [p for p in stats.improvements(scores) if p.x == "pgpe"]
        assert [row[0] for row in table["rows"]] == ["openai", "pgpe"]
        assert table["rows"][1][2] == {"value": summary_pgpe.iqm, "low": summary_pgpe.iqm_low,
                                       "high": summary_pgpe.iqm_high, "digits": 1}
        assert table["rows"][0][5] == "—"
        assert table["rows"][1][5]["value"] == pgpe_over_openai.probability
        assert table["rows"][1][6] == ", ".join(f"{value:.1f}" for value in scores["pgpe"])
    assert [row[0] for row in record["notes"]["kinds"]["rows"]] == ["openai", "pgpe"]

    trained = run_files(runs)
    again = run("strategies.py", *args, "--results", str(tmp_path / "again"), cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert run_files(runs) == trained  # nothing trained again
    repeated = record_of(tmp_path / "again")
    assert {key: repeated["notes"][key] for key in ("static", "hebbian", "kinds")} == {
        key: record["notes"][key] for key in ("static", "hebbian", "kinds")}


@pytest.mark.parametrize("argv, message", [
    (["--strategies", "openai,nope"], "--strategies openai,nope: give distinct names"),
    (["--kinds", "static,static"], "--kinds static,static: give distinct names"),
    (["--seeds", "0"], "argument --seeds: must be a whole number >= 1, got 0"),
])
def test_strategies_refuses_bad_input_in_one_line(tmp_path, argv, message):
    result = run("strategies.py", *argv, "--results", str(tmp_path / "records"), cwd=tmp_path)
    assert result.returncode == 2 and message in result.stderr.splitlines()[-1]
    assert not (tmp_path / "records").exists() and not (tmp_path / "runs").exists()


def test_modern_es_record_is_the_evaluations_of_the_two_runs(tmp_path):
    args = ["--environment", "Ant-v5,AntAsymRight-v5", "--popsize", "2", "--generations", "5", "--episodes", "2"]
    first = run("modern_es.py", *args, "--results", str(tmp_path / "first"), cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    record = record_of(tmp_path / "first")
    table = record["notes"]["results"]
    assert table["columns"][:5] == ["settings", "Ant-v5: return", "Ant-v5: forward x", "AntAsymRight-v5: return",
                                    "AntAsymRight-v5: forward x"]
    folder = tmp_path / "runs" / "modern_es" / "Ant-v5+AntAsymRight-v5"
    for row, setting in zip(table["rows"], ("faithful", "modern"), strict=True):
        [run_dir] = [path.parent for path in (folder / setting).glob("*/metrics.csv")]
        config = json.loads((run_dir / "config.json").read_text())
        assert config["es"]["optimizer"] == ("adam" if setting == "modern" else "sgd")
        evaluation = json.loads((folder / setting / f"evaluation-{run_dir.name}.json").read_text())
        assert evaluation["seed"] == 2**31 and evaluation["weights"]["generation"] == 5
        ant, right = evaluation["environments"]
        assert row[0] == setting and row[1] == f"{ant['mean']:,.1f} ± {ant['std']:,.1f}"
        assert row[4] == f"{right['forward_mean']:,.1f} ± {right['forward_std']:,.1f} m"
        assert record["measures"][f"{setting}_Ant-v5_return"]["values"] == ant["returns"]
        last = (run_dir / "metrics.csv").read_text().splitlines()[-1].split(",")
        assert row[5].endswith("(generation 5)") and last[0] == "5"
        # the centre's evaluations, read from metrics.csv by a plain loop
        header, *lines = (run_dir / "metrics.csv").read_text().splitlines()
        columns = header.split(",")
        logged = []
        for line in lines:
            cells = dict(zip(columns, line.split(","), strict=True))
            if cells["center_eval_mean"] not in ("", "nan"):
                logged.append((int(cells["generation"]), float(cells["center_eval_mean"])))
        assert [generation for generation, _ in logged] == [5]  # --eval_every 5, 5 generations
        [generation, mean] = logged[0]
        shown = f"{mean:,.1f} (generation {generation})"
        assert record["notes"]["centre"]["rows"][("faithful", "modern").index(setting)] == [
            setting, 1, int(mean < 0), 0, shown, shown, shown]
    trained = run_files(folder)
    again = run("modern_es.py", *args, "--results", str(tmp_path / "again"), cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert {path: stamp for path, stamp in run_files(folder).items() if "evaluation" not in path.name} == {
        path: stamp for path, stamp in trained.items() if "evaluation" not in path.name}
    assert record_of(tmp_path / "again")["notes"]["results"] == table
    assert record_of(tmp_path / "again")["notes"]["centre"] == record["notes"]["centre"]


def test_modern_es_centre_row_counts_as_a_plain_loop_does(tmp_path):
    """Several evaluations: below zero, lower than the one before, and the first of equal highs; a generation
    without an evaluation (nan) is not one."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import modern_es

    evaluations = [(5, -3.0, 1.0), (10, 7.5, 0.5), (15, 2.0, 0.1), (20, 7.5, 0.0), (25, -1.0, 2.0)]
    lines = [f"{generation},{mean},{std}" for generation, mean, std in evaluations] + ["26,nan,nan"]
    (tmp_path / "metrics.csv").write_text("generation,center_eval_mean,center_eval_std\n" + "\n".join(lines) + "\n")
    below = falls = 0
    for index, (_, mean, _) in enumerate(evaluations):
        below += mean < 0
        falls += index > 0 and mean < evaluations[index - 1][1]
    assert (below, falls) == (2, 2)
    assert modern_es.centre_row("modern", tmp_path) == [
        "modern", 5, below, falls, "-3.0 (generation 5)", "7.5 (generation 10)", "-1.0 (generation 25)"]


def test_compare_records_its_table(tmp_path):
    """experiments/reservoir_front/compare.py --record: its printed table, as a record."""
    need("reservoirs")
    sys.path.insert(0, str(ROOT))
    from experiments.reservoir_front import compare

    args = ["--seeds", "1", "2", "--generations", "1", "--popsize", "2", "--episodes", "2", "--threads", "1",
            "--arms", "static", "static+reservoir", "--folder", str(tmp_path / "runs"), "--record",
            str(tmp_path / "records")]
    done = subprocess.run([sys.executable, str(ROOT / "experiments" / "reservoir_front" / "compare.py"), *args],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    record = record_of(tmp_path / "records")
    assert record["timed"] is False and "compare.py" in record["command"]
    results = {arm: {int(seed): value for seed, value in runs.items()}
               for arm, runs in json.loads((tmp_path / "runs" / "results.json").read_text()).items()}
    table = record["notes"]["results"]
    assert table["columns"] == ["arm", "seed 1", "seed 2", "mean"]
    expected = [[arm, *(f"{value:.1f}" for value in (*per_seed, mean))]
                for arm, per_seed, mean, _ in compare.means(results, [1, 2])]
    assert table["rows"] == expected
    shown = (tmp_path / "runs" / "results.md").read_text().splitlines()[2:]
    assert [line.split(" | ")[0].strip("| ") for line in shown] == ["static", "static+reservoir"]
    for line, row in zip(shown, expected, strict=True):
        assert f"**{row[3]}**" in line
    for arm, per_seed, _, _ in compare.means(results, [1, 2]):
        assert record["measures"][arm]["values"] == per_seed


def test_ermrl_example_records_the_tests_summaries_and_the_studies_trials(tmp_path):
    """experiments/ermrl_example.py --record: each row is a model's mean return in test.py's own summary, the
    published input is tested in its own folder on the same study, the trials are the journals', and the same
    command again runs no script and writes the same tables."""
    need("reservoirs")
    import optuna

    from reservoirs import study

    args = ["--nb_trials", "1", "--HP_training_steps", "64", "--training_steps", "64", "--seeds", "0", "1",
            "--folder", str(tmp_path / "runs"), "--record", str(tmp_path / "records")]

    def example(*more: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, str(ROOT / "experiments" / "ermrl_example.py"), *args, *more],
                              cwd=tmp_path, capture_output=True, text=True, timeout=600)

    done = example()
    assert done.returncode == 0, done.stderr
    record = record_of(tmp_path / "records")
    assert record["timed"] is False and "ermrl_example.py" in record["command"]
    runs = tmp_path / "runs"

    def summary(folder: Path, h_test: str, seed: int) -> dict:
        return json.loads((folder / "models" / f"CartPole-v1_{h_test}" / f"test_0k_steps_seed_{seed}.json").read_text())

    tests = [summary(runs, "del_obs_demo", seed) for seed in (0, 1)]
    published = summary(runs / "published_input", "del_obs_demo", 0)
    zero = summary(runs, "del_obs_zero", 0)
    assert (published["zero_action"], zero["zero_action"], tests[0]["zero_action"]) == (True, True, False)
    assert published["trial"] == tests[0]["trial"] and published["params"] == tests[0]["params"]
    rows = record["notes"]["results"]["rows"]
    assert [row[0] for row in rows[:4]] == ["`PPO`", "`RES_PPO_0.0003`", "`RES_PPO_0.0001`", "`RES_PPO_0.00005`"]

    def cell(entry: dict) -> str:
        return f"{entry['mean_return_last_10']:.1f} ({entry['episodes']})"

    for row, model in zip(rows, ("PPO", "RES_PPO_0.0003", "RES_PPO_0.0001", "RES_PPO_0.00005"), strict=False):
        assert row[1:] == [cell(tests[0]["models"][model]), cell(tests[1]["models"][model])]
        assert record["measures"][model]["values"] == [test["models"][model]["mean_return_last_10"] for test in tests]
    assert rows[4][1:] == [cell(published["models"]["RES_PPO_0.0003"]), "–"]
    assert rows[5][1:] == [cell(zero["models"]["RES_PPO_0.0003"]), "–"]
    trials = record["notes"]["trials"]
    for h_test, fitness_column in (("del_obs_demo", 3), ("del_obs_zero", 6)):
        name = study.study_name("CartPole-v1", h_test, training_steps=64)
        [trial] = optuna.load_study(study_name=name, storage=study.open_journal(runs / study.journal_path(name))).trials
        assert trials["rows"][0][fitness_column] == f"{trial.value:.2f}"
        assert trials["columns"][fitness_column] == f"{h_test}: fitness"
    assert [row[0] for row in record["notes"]["minutes"]["rows"]] == [
        "evolve del_obs_demo", "test del_obs_demo seed 0", "test del_obs_demo seed 1", "published input",
        "evolve del_obs_zero", "test del_obs_zero seed 0"]
    def outputs() -> dict[Path, int]:  # the scripts' (the table, results.md, is written again)
        return {path: stamp for path, stamp in run_files(runs).items() if path.name != "results.md"}

    written = outputs()
    again = example("--record", str(tmp_path / "again"))
    assert again.returncode == 0, again.stderr
    assert "$ " not in again.stdout and outputs() == written
    assert record_of(tmp_path / "again")["notes"] == record["notes"]


def test_ermrl_example_refuses_a_seed_twice(tmp_path):
    done = subprocess.run([sys.executable, str(ROOT / "experiments" / "ermrl_example.py"), "--seeds", "0", "0",
                           "--folder", str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and done.stderr.strip().splitlines()[-1].endswith("--seeds 0 0: each seed once")
    assert not any(tmp_path.iterdir())


def test_ermrl_example_refuses_a_folder_it_cannot_make_and_a_broken_summary(tmp_path):
    need("reservoirs")
    blocked = tmp_path / "file"
    blocked.write_text("")
    done = subprocess.run([sys.executable, str(ROOT / "experiments" / "ermrl_example.py"), "--folder",
                           str(blocked / "runs")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "--folder" in done.stderr.strip().splitlines()[-1]
    summary = tmp_path / "runs" / "models" / "CartPole-v1_del_obs_demo" / "test_0k_steps_seed_0.json"
    summary.parent.mkdir(parents=True)
    summary.write_text("{")  # a summary cut short: refused, kept as it is
    done = subprocess.run([sys.executable, str(ROOT / "experiments" / "ermrl_example.py"), "--nb_trials", "1",
                           "--HP_training_steps", "64", "--training_steps", "64", "--seeds", "0", "--folder",
                           str(tmp_path / "runs")], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 2, done.stderr
    assert "is not a summary test.py wrote" in done.stderr.strip().splitlines()[-1]
    assert summary.read_text() == "{"
