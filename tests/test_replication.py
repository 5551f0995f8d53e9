"""The replication report (experiments/replication.py): results/paper/REPLICATION.md is what the campaign's files give
(``--check``), its verdicts follow the rules experiments/verdicts.py states (exact cases at their boundaries), and
``--check`` tells a page that is behind newly evaluated runs (exit 0) from one that differs otherwise (exit 1).
"""

from pathlib import Path

import pytest

from experiments import replication
from experiments.replication_files import Group, Report
from experiments.verdicts import (
    ANT_BODIES,
    NOT_REPRODUCED,
    REPRODUCED,
    UNDECIDED,
    Cited,
    Claim,
    Trace,
    adaptation_verdict,
    verdict_of,
)

ROOT = Path(__file__).resolve().parent.parent


def test_the_committed_page_is_what_the_files_give(capsys):
    assert replication.main(["--check"]) == 0, capsys.readouterr().out


def report(runs: int = 3, probability=(0.5, 0.2, 0.8), hebbian_mean=(850.0, 800.0, 900.0)) -> Report:
    groups = {"hebbian": Group("hebbian", runs, hebbian_mean, hebbian_mean),
              "static": Group("static", runs, (700.0, 650.0, 750.0), (700.0, 650.0, 750.0))}
    p, low, high = probability
    return Report(Path("."), groups, {("hebbian", "static"): (p, low, high),
                                      ("static", "hebbian"): (1 - p, 1 - high, 1 - low)})


HIGHER = Claim("Hebbian higher", "-", "x", "E", ("hebbian", "static"))


@pytest.mark.parametrize("probability, status", [
    ((0.9, 0.51, 1.0), REPRODUCED), ((0.9, 0.5, 1.0), UNDECIDED), ((0.1, 0.0, 0.49), NOT_REPRODUCED),
    ((0.1, 0.0, 0.5), UNDECIDED), ((0.5, 0.0, 1.0), UNDECIDED)])
def test_a_claim_that_one_kind_scores_higher_is_decided_by_p_x_over_y(probability, status):
    assert verdict_of(HIGHER, report(probability=probability)).status == status


@pytest.mark.parametrize("cited, status", [
    (Cited("hebbian", 800, 10), REPRODUCED), (Cited("hebbian", 900, 10), REPRODUCED),
    (Cited("hebbian", 905, 10), UNDECIDED), (Cited("hebbian", 910, 10), UNDECIDED),
    (Cited("hebbian", 910.5, 10), NOT_REPRODUCED), (Cited("hebbian", 780, 19), NOT_REPRODUCED),
    (Cited("hebbian", 780, 20), UNDECIDED)])
def test_a_cited_figure_is_decided_by_the_interval_of_the_kinds_mean(cited, status):
    claim = Claim("level", "-", "x", "E", None, (cited,))
    assert verdict_of(claim, report()).status == status


def test_too_few_runs_or_no_report_decide_nothing_and_a_failing_part_decides_the_row():
    both = Claim("both", "-", "x", "E", ("hebbian", "static"), (Cited("hebbian", 850, 10),))
    decided = report(runs=3, probability=(1.0, 1.0, 1.0))
    assert verdict_of(both, decided).status == REPRODUCED
    verdict = verdict_of(both, report(runs=2, probability=(1.0, 1.0, 1.0)))
    assert verdict.status == UNDECIDED and "2 Hebbian runs, 2 static runs evaluated so far" in verdict.reason
    assert verdict_of(both, None).status == UNDECIDED
    low = report(runs=3, probability=(1.0, 1.0, 1.0), hebbian_mean=(100.0, 90.0, 110.0))
    verdict = verdict_of(both, low)
    assert verdict.status == NOT_REPRODUCED and verdict.reason.startswith("the Hebbian runs' mean 100 [90, 110]")


def walking(walks: bool) -> Trace:
    return Trace(seed=0, steps=960, forward=1.0 if walks else 0.1, lowest=0.5, turned=0.9)


def test_the_adaptation_claim_needs_most_runs_walking_from_step_100_on_every_body():
    bodies = ANT_BODIES

    def runs(pattern: list[list[bool]]) -> dict:  # run -> body -> episodes
        return {f"run{i}": {body: [walking(walks) for walks in episodes] for body in bodies}
                for i, episodes in enumerate(pattern)}

    assert adaptation_verdict(runs([[True, True, False]] * 2)).status == UNDECIDED
    assert adaptation_verdict(runs([[True, True, False]] * 3)).status == REPRODUCED
    verdict = adaptation_verdict(runs([[True, False, False]] * 2 + [[True, True, True]]))
    assert verdict.status == NOT_REPRODUCED and "1 of 3 runs walk from step 100" in verdict.reason
    # an episode that ends before step 200, or whose torso touches the alive height, does not walk
    assert not Trace(0, 199, 1.0, 0.5, 0.9).walks and not Trace(0, 960, 1.0, 0.26, 0.9).walks
    assert Trace(0, 200, 0.5, 0.27, 0.9).walks


def campaign_view(tmp_path: Path, names: list[str]) -> Path:
    """A folder holding some of the campaign's CarRacing runs and its CarRacing report (links to them)."""
    runs = tmp_path / "paper"
    runs.mkdir()
    for name in [*names, "carracing_report"]:
        (runs / name).symlink_to(replication.RUNS / name)
    return runs


def test_check_tells_a_page_behind_new_runs_from_one_that_differs(tmp_path, capsys):
    runs = campaign_view(tmp_path, ["carracing_hebbian_seed1", "carracing_static_seed1"])
    records = tmp_path / "no records"
    argv = ["--runs", str(runs), "--records", str(records)]
    assert replication.main([*argv, "--check"]) == 1  # no page yet
    assert replication.main(argv) == 0
    page = runs / replication.PAGE_NAME
    written = page.read_text()
    assert "<!-- runs: carracing_hebbian_seed1 carracing_static_seed1 -->" in written
    assert "No record of `experiments/original_ant.py` yet." in written
    assert replication.main([*argv, "--check"]) == 0
    (runs / "carracing_static_seed2").symlink_to(replication.RUNS / "carracing_static_seed2")
    capsys.readouterr()
    assert replication.main([*argv, "--check"]) == 0
    assert "behind the runs evaluated since it was written (carracing_static_seed2)" in capsys.readouterr().out
    assert replication.main(argv) == 0 and replication.main([*argv, "--check"]) == 0
    caught_up = page.read_text()
    assert "carracing_static_seed2" in caught_up
    page.write_text(caught_up.replace("not yet decided", "reproduced", 1))  # the same runs, another verdict
    assert replication.main([*argv, "--check"]) == 1
    assert "differs from what the runs' files give" in capsys.readouterr().out


def test_an_unreadable_report_is_one_line(tmp_path, capsys):
    runs = tmp_path / "paper"
    (runs / "carracing_report" / "CarRacing-v3").mkdir(parents=True)
    (runs / "carracing_report" / "CarRacing-v3" / "summary.csv").write_text("group,runs\nstatic,three\n")
    assert replication.main(["--runs", str(runs), "--check"]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "not a report of the campaign" in error
    assert replication.main(["--runs", str(tmp_path / "missing")]) == 2
    assert "not a folder" in capsys.readouterr().err
