"""report/stats.py and report_runs.py on hand-made run folders, against the statistics computed plainly.

The run folders are real: metrics.csv written by the project's own writer (es.files.write_metrics),
config.json and evaluation.json as the scripts write them (and one evaluation.json written by
evaluate_static.py itself). rliable is the optional statistics extra.
"""

from __future__ import annotations

import csv
import itertools
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from es import files
from report import stats
from tests.extras import need

ROOT = Path(__file__).resolve().parent.parent
REPS = 300  # bootstrap replications: enough to test, few enough to be quick


@pytest.fixture
def rliable():
    """The statistics extra; the test is skipped, naming it, where it is missing."""
    need("stats")


def metrics_row(generation: int, center: float, center_eval: float | str = "") -> dict:
    row = {name: 0 for name in files.METRICS_COLUMNS}
    row.update(generation=generation, center_return=center, center_eval_mean=center_eval, center_eval_std="",
               center_rank="", episode_cap="")
    return row


def make_run(folder: Path, name: str, centres: list[float], env: str = "CartPole-v1",
             evaluations: list[float | str] | None = None, returns: list[float] | None = None) -> Path:
    """A run folder as training leaves it: config.json and metrics.csv (and evaluation.json with ``returns``)."""
    run = folder / name
    run.mkdir(parents=True)
    evaluations = evaluations or [""] * len(centres)
    rows = [metrics_row(number + 1, centre, evaluation)
            for number, (centre, evaluation) in enumerate(zip(centres, evaluations))]
    files.write_metrics(run / "metrics.csv", rows)
    files.write_json(run / "config.json", {"env": {"env_ids": [env]}, "run": {"seed": 1}})
    if returns is not None:
        files.write_json(run / "evaluation.json", {"environments": [{"environment": env, "returns": returns}]})
    return run


def group_of(tmp_path: Path, name: str, finals: list[float]) -> str:
    for number, final in enumerate(finals):
        make_run(tmp_path / name, f"seed{number}", [0.0, final])
    return f"{name}={tmp_path / name}"


def plain_iqm(values: list[float]) -> float:
    """The mean of the middle half: drop the lowest and highest quarter (a multiple of 4 runs here)."""
    ordered = sorted(values)
    quarter = len(ordered) // 4
    middle = ordered[quarter:len(ordered) - quarter]
    return sum(middle) / len(middle)


def plain_improvement(x: list[float], y: list[float]) -> float:
    """P(X > Y): the fraction of pairs where x wins, ties counting one half."""
    wins = sum(1.0 if a > b else 0.5 if a == b else 0.0 for a, b in itertools.product(x, y))
    return wins / (len(x) * len(y))


def test_scores_of_a_run(tmp_path):
    plain = make_run(tmp_path, "plain", [10.0, 40.0, 30.0])
    assert stats.final_score(plain) == 30.0
    assert stats.best_score(plain) == 40.0
    # with --eval_every the centre's evaluation mean counts where it exists
    evaluated = make_run(tmp_path, "evaluated", [10.0, 40.0, 30.0], evaluations=["", 35.5, 20.25])
    assert stats.final_score(evaluated) == 20.25
    assert stats.best_score(evaluated) == 35.5
    assert stats.evaluation_score(make_run(tmp_path, "eval", [1.0], returns=[3.0, 4.0, 8.0])) == 5.0
    with pytest.raises(stats.StatsError, match="no evaluation.json"):
        stats.evaluation_score(plain)


def test_the_evaluation_score_reads_what_the_evaluate_script_writes(tmp_path):
    """evaluation.json as evaluate_static.py --json writes it, not a hand-made one: the score is the mean of the
    returns it holds, over all its environments or of the one named; another name is refused, naming those it
    has."""
    python = [sys.executable]
    subprocess.run([*python, "train_static.py", "--environment", "CartPole-v1", "--popsize", "4", "--generations",
                    "1", "--threads", "1", "--seed", "3", "--folder", str(tmp_path)],
                   cwd=ROOT, check=True, capture_output=True, timeout=600)
    (run,) = [path for path in tmp_path.iterdir() if path.is_dir()]
    subprocess.run([*python, "evaluate_static.py", "--path_weights", str(run), "--episodes", "3", "--json",
                    str(run / "evaluation.json")], cwd=ROOT, check=True, capture_output=True, timeout=600)
    (written,) = files.read_json(run / "evaluation.json")["environments"]
    assert len(written["returns"]) == 3
    assert stats.evaluation_score(run) == float(np.mean(written["returns"]))
    assert stats.evaluation_score(run, "CartPole-v1") == float(np.mean(written["returns"]))
    with pytest.raises(stats.StatsError, match="has no environment Pendulum-v1; it has CartPole-v1"):
        stats.evaluation_score(run, "Pendulum-v1")


def test_iqm_and_mean_exact_with_their_intervals(tmp_path, rliable):
    finals = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 100.0]
    scores = {"a": finals}
    summary, = stats.summarise(scores, reps=REPS, seed=0)
    assert summary.iqm == pytest.approx(plain_iqm(finals), abs=1e-12) == 4.5
    assert summary.mean == pytest.approx(sum(finals) / len(finals)) == 16.0
    assert summary.median == 4.5
    assert summary.iqm_low <= summary.iqm <= summary.iqm_high
    assert summary.mean_low <= summary.mean <= summary.mean_high
    assert summary.mean_high > summary.mean_low  # the outlier makes the mean's interval wide
    again, = stats.summarise(scores, reps=REPS, seed=0)
    assert again == summary  # deterministic for a fixed seed
    other, = stats.summarise(scores, reps=REPS, seed=1)
    assert (other.iqm, other.mean) == (summary.iqm, summary.mean)


def test_probability_of_improvement_exact(tmp_path, rliable):
    x, y = [1.0, 2.0, 3.0, 4.0], [0.0, 1.0, 2.0, 3.0]
    pairs = {(pair.x, pair.y): pair for pair in stats.improvements({"x": x, "y": y}, reps=REPS, seed=0)}
    assert pairs["x", "y"].probability == pytest.approx(plain_improvement(x, y)) == pytest.approx(11.5 / 16)
    assert pairs["y", "x"].probability == pytest.approx(plain_improvement(y, x)) == pytest.approx(4.5 / 16)
    for pair in pairs.values():
        assert 0 <= pair.low <= pair.probability <= pair.high <= 1
    assert stats.improvements({"x": x, "y": y}, reps=REPS, seed=0) == list(pairs.values())


def test_performance_profile_is_the_fraction_above(tmp_path, rliable):
    scores = {"a": [1.0, 2.0, 3.0, 4.0], "b": [2.0, 2.0, 5.0, 6.0]}
    taus = np.array([0.0, 1.5, 2.0, 4.5, 6.0])
    curves = stats.profiles(scores, taus, reps=REPS, seed=0)
    for name, values in scores.items():
        fraction, low, high = curves[name]
        expected = [sum(value > tau for value in values) / len(values) for tau in taus]
        np.testing.assert_allclose(fraction, expected)
        assert np.all(low <= fraction + 1e-12) and np.all(fraction <= high + 1e-12)


def test_report_files_from_run_folders(tmp_path, rliable):
    static = group_of(tmp_path, "static", [10.0, 20.0, 30.0, 40.0])
    hebbian = group_of(tmp_path, "hebbian", [15.0, 25.0, 35.0, 500.0])
    out = tmp_path / "out"
    result = stats.report([static, hebbian], out, reps=REPS, seed=3)
    with open(out / "summary.csv", newline="") as handle:
        rows = {row["group"]: row for row in csv.DictReader(handle)}
    assert float(rows["static"]["iqm"]) == plain_iqm([10.0, 20.0, 30.0, 40.0]) == 25.0
    assert float(rows["hebbian"]["mean"]) == 143.75
    with open(out / "improvement.csv", newline="") as handle:
        pairs = {(row["x"], row["y"]): float(row["probability"]) for row in csv.DictReader(handle)}
    assert pairs["hebbian", "static"] == pytest.approx(plain_improvement([15, 25, 35, 500], [10, 20, 30, 40]))
    assert "| static | 4 | 25.0 [" in (out / "summary.md").read_text()
    assert (out / "report.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(result.scores["static"]) == 4
    first = (out / "summary.csv").read_text()
    stats.report([static, hebbian], out, reps=REPS, seed=3)
    assert (out / "summary.csv").read_text() == first


def test_a_group_of_one_run_has_no_interval(tmp_path, rliable):
    """One run per group: the bootstrap resamples that run alone, so the report gives the point and says there
    is no interval, instead of the point twice as a 95 % interval; a pair with such a group likewise."""
    static = group_of(tmp_path, "static", [10.0])
    hebbian = group_of(tmp_path, "hebbian", [15.0, 25.0, 35.0, 500.0])
    text = stats.report([static, hebbian], tmp_path / "out", reps=REPS, seed=3).markdown
    assert f"| static | 1 | 10.0 {stats.NO_INTERVAL} | 10.0 {stats.NO_INTERVAL} | 10.0 |" in text
    assert "| hebbian | 4 | 30.0 [" in text
    assert f"| hebbian | static | 1.00 {stats.NO_INTERVAL} |" in text
    assert f"| static | hebbian | 0.00 {stats.NO_INTERVAL} |" in text
    assert text.rstrip().endswith("static: one run, so no interval, and a probability of improvement against it "
                                  "compares single runs; train more seeds before reading a difference from this "
                                  "report.")
    assert (tmp_path / "out" / "summary.md").read_text() == text
    two = stats.report([group_of(tmp_path, "a", [1.0, 2.0]), group_of(tmp_path, "b", [3.0, 4.0])],
                       tmp_path / "two", reps=REPS, seed=3).markdown
    assert "no interval" not in two and "| a | 2 | 1.5 [" in two


def test_refusals(tmp_path):
    static = group_of(tmp_path, "static", [1.0, 2.0])
    with pytest.raises(stats.StatsError, match="no run folder"):
        stats.collect([f"empty={tmp_path / 'nothing'}"], "final")
    with pytest.raises(stats.StatsError, match="NAME=RUN_FOLDERS"):
        stats.collect(["static"], "final")
    with pytest.raises(stats.StatsError, match="in both groups"):
        stats.collect([static, static.replace("static=", "again=")], "final")
    make_run(tmp_path / "cheetah", "seed1", [1.0], env="HalfCheetah-v5")
    with pytest.raises(stats.StatsError, match="different environments"):
        stats.collect([static, f"cheetah={tmp_path / 'cheetah'}"], "final")


def script(*argv: str, code: str = "") -> subprocess.CompletedProcess:
    prelude = f"import sys, runpy; {code}sys.argv = ['report_runs.py', *{list(argv)!r}]; " \
              "runpy.run_path('report_runs.py', run_name='__main__')"
    return subprocess.run([sys.executable, "-c", prelude], check=False, cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


def test_command_line(tmp_path, rliable):
    static = group_of(tmp_path, "static", [1.0, 2.0, 3.0])
    other = group_of(tmp_path, "other", [2.0, 3.0, 4.0])
    done = script("--group", static, "--group", other, "--out", str(tmp_path / "out"), "--reps", "200")
    assert done.returncode == 0, done.stderr
    assert "| other | 3 | 3.0 [" in done.stdout
    bad = script("--group", f"x={tmp_path / 'missing'}", "--out", str(tmp_path / "out2"))
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "no run folder" in bad.stderr


def test_without_rliable_one_line_names_the_extra(tmp_path):
    """On every install: rliable hidden (its import fails) where it is present."""
    static = group_of(tmp_path, "static", [1.0, 2.0, 3.0])
    missing = script("--group", static, "--out", str(tmp_path / "out"), code="sys.modules['rliable'] = None; ")
    assert missing.returncode == 2
    assert missing.stderr.strip().splitlines() == [
        ("report_runs.py: error: the statistics need rliable, which is not installed; install it with: "
         "pip install -r requirements-stats.txt")]
    assert not (tmp_path / "out").exists()


def test_paper_report_static_against_hebbian(tmp_path, rliable):
    """experiments/paper.py ant report: each seed's newest evaluated run, one report per evaluation body."""
    bodies = ["AntBulletEnv-v0", "AntAsymRightBulletEnv-v0", "AntAsymLeftBulletEnv-v0"]
    returns = {"static": [[100.0, 110.0], [90.0, 95.0], [10.0, 30.0]],
               "hebbian": [[60.0, 70.0], [50.0, 55.0], [40.0, 44.0]]}
    for kind, per_body in returns.items():
        for seed in (1, 2, 3, 4):
            run = make_run(tmp_path / f"ant_{kind}_seed{seed}", f"2026_run_seed{seed}", [0.0], env="AntBulletEnv-v0")
            (run / "checkpoint.npz").write_bytes(b"")  # what marks a run folder for experiments/paper.py
            evaluations = [{"environment": body, "returns": [value + seed for value in values]}
                           for body, values in zip(bodies, per_body)]
            files.write_json(run / "evaluation.json", {"environments": evaluations})
            # the best centre's evaluation, beside it: every return 1000 lower, seed 4's file missing
            if seed < 4:
                best = [{"environment": body, "returns": [value + seed - 1000 for value in values]}
                        for body, values in zip(bodies, per_body)]
                files.write_json(run / "evaluation_best.json", {"environments": best})
    done = subprocess.run([sys.executable, "experiments/paper.py", "ant", "report", "--runs", str(tmp_path),
                           "--reps", str(REPS)],
                          check=False, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    best = subprocess.run([sys.executable, "experiments/paper.py", "ant", "report", "--centre", "best", "--runs",
                           str(tmp_path), "--reps", str(REPS)],
                          check=False, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert best.returncode == 0, best.stderr
    for body, (static, hebbian) in zip(bodies, zip(returns["static"], returns["hebbian"])):
        with open(tmp_path / "ant_report_best" / body / "summary.csv", newline="") as handle:
            rows = {row["group"]: row for row in csv.DictReader(handle)}
        # the three runs with a best centre's evaluation, seeds 1..3: their mean, 1000 lower
        assert [int(rows[kind]["runs"]) for kind in ("static", "hebbian")] == [3, 3]
        assert float(rows["static"]["mean"]) == pytest.approx(sum(static) / 2 + 2 - 1000)
        assert float(rows["hebbian"]["mean"]) == pytest.approx(sum(hebbian) / 2 + 2 - 1000)
    assert "Score of a run: evaluation_best" in best.stdout
    for body, (static, hebbian) in zip(bodies, zip(returns["static"], returns["hebbian"])):
        with open(tmp_path / "ant_report" / body / "summary.csv", newline="") as handle:
            rows = {row["group"]: row for row in csv.DictReader(handle)}
        # seeds add 1..4 to both episodes: the IQM of four runs is the mean of the middle two (seeds 2, 3)
        assert float(rows["static"]["iqm"]) == pytest.approx(sum(static) / 2 + 2.5)
        assert float(rows["hebbian"]["iqm"]) == pytest.approx(sum(hebbian) / 2 + 2.5)
    with open(tmp_path / "ant_report" / bodies[2] / "improvement.csv", newline="") as handle:
        pairs = {(row["x"], row["y"]): float(row["probability"]) for row in csv.DictReader(handle)}
    assert pairs["hebbian", "static"] == 1.0  # on the unseen body every Hebbian run beats every static one


def test_paper_report_of_real_carracing_runs(tmp_path, rliable):
    """experiments/paper.py carracing report over runs that paper.py itself trained and evaluated (small ones):
    the experiment file's CarRacing-v0 is the evaluation's CarRacing-v3, and each kind's mean is the mean of its
    runs' evaluation means."""
    from experiments import paper_campaign

    scores = {}
    for kind in ("static", "hebbian"):
        for seed in (1, 2):
            folder = tmp_path / f"carracing_{kind}_seed{seed}"
            subprocess.run([sys.executable, "experiments/paper.py", "carracing", kind, "--seed", str(seed),
                            "--popsize", "4", "--generations", "1", "--episodes", "2", "--threads", "1", "--folder",
                            str(folder)], check=True, cwd=ROOT, capture_output=True, timeout=600)
            (evaluation,) = folder.glob("*/evaluation.json")
            (written,) = files.read_json(evaluation)["environments"]
            scores.setdefault(kind, []).append(float(np.mean(written["returns"])))
        # a chunk's end writes the report once both kinds have an evaluated run, not before
        paper_campaign.write_pages(tmp_path, "carracing")
        assert (tmp_path / "carracing_report").exists() == (kind == "hebbian")
        # and with it the replication report, which reads every experiment's report
        assert (tmp_path / "REPLICATION.md").exists() == (kind == "hebbian")
    assert "| CarRacing: the Hebbian network drives better than the static one |" in (
        tmp_path / "REPLICATION.md").read_text()
    # the runs named relative to the folder of runs, so that the report reads the same from any clone
    with open(tmp_path / "carracing_report" / "CarRacing-v3" / "scores.csv", newline="") as handle:
        named = sorted(row["run"] for row in csv.DictReader(handle))
    assert named == sorted(path.parent.relative_to(tmp_path).as_posix()
                           for path in tmp_path.glob("carracing_*_seed*/*/evaluation.json"))
    pages = {name: (tmp_path / "carracing_report" / "CarRacing-v3" / name).read_bytes()
             for name in ("summary.md", "summary.csv", "improvement.csv", "scores.csv")}
    done = subprocess.run([sys.executable, "experiments/paper.py", "carracing", "report", "--runs", str(tmp_path)],
                          check=False, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert {name: (tmp_path / "carracing_report" / "CarRacing-v3" / name).read_bytes() for name in pages} == pages
    # committed with the runs by results/paper/.gitignore
    (tmp_path / ".gitignore").write_bytes((ROOT / "results" / "paper" / ".gitignore").read_bytes())
    subprocess.run(["git", "init", "-q"], cwd=tmp_path, check=True)
    subprocess.run(["git", "add", "-A"], cwd=tmp_path, check=True)
    listed = subprocess.run(["git", "ls-files", "carracing_report"], cwd=tmp_path, check=True, capture_output=True,
                            text=True).stdout.split()
    assert listed == [f"carracing_report/CarRacing-v3/{name}" for name in
                      ("improvement.csv", "report.png", "scores.csv", "summary.csv", "summary.md")]
    assert "## CarRacing-v3" in done.stdout
    with open(tmp_path / "carracing_report" / "CarRacing-v3" / "summary.csv", newline="") as handle:
        rows = {row["group"]: row for row in csv.DictReader(handle)}
    for kind, values in scores.items():
        assert int(rows[kind]["runs"]) == 2
        assert float(rows[kind]["mean"]) == pytest.approx(np.mean(values))


@pytest.mark.parametrize("argv, words", [
    (["ant", "static", "--centre", "best"], "--centre goes with report"),
    (["ant", "report", "--centre", "middle"], "argument --centre: invalid choice: 'middle'"),
])
def test_paper_report_centre_is_refused_in_one_line(argv, words):
    done = subprocess.run([sys.executable, "experiments/paper.py", *argv], check=False, cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2 and words in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_paper_report_names_the_missing_best_evaluation(tmp_path, rliable):
    for kind in ("static", "hebbian"):
        run = make_run(tmp_path / f"ant_{kind}_seed1", "2026_run_seed1", [0.0], env="AntBulletEnv-v0")
        (run / "checkpoint.npz").write_bytes(b"")
        files.write_json(run / "evaluation.json", {"environments": [{"environment": "AntBulletEnv-v0",
                                                                     "returns": [1.0]}]})
    done = subprocess.run([sys.executable, "experiments/paper.py", "ant", "report", "--centre", "best", "--runs",
                           str(tmp_path)], check=False, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [  # (both kinds lack one: the first kind of the registry is named)
        f"paper.py: error: no hebbian run in {tmp_path}/ant_hebbian_seed* has evaluation_best.json; run python "
        "experiments/paper.py ant hebbian --seed N first"]
    assert not (tmp_path / "ant_report_best").exists()
