"""The static ant's study: variant files of the paper's experiment (``paper.py --variant``), the two episode rules
the study changes (experiments/static_ant/), and its page (experiments/stand.py), computed from the runs' files as a
plain loop over metrics.csv gives it.
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from experiments import stand

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "SDL_VIDEODRIVER": "dummy"}
SIGMA = "experiments/static_ant/sigma.toml"


def paper(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "experiments" / "paper.py"), *args], cwd=cwd, env=ENV,
                          capture_output=True, text=True, timeout=300)


def test_the_committed_page_is_what_the_files_give(capsys):
    assert stand.main(["--check"]) == 0, capsys.readouterr().out


def test_a_variant_changes_only_its_settings_and_names_its_runs_folder():
    # seed 9: no committed run, whose config.json a dry run would read and resume instead of training anew
    result = paper("ant", "static", "--variant", SIGMA, "--seed", "9", "--dry-run")
    assert result.returncode == 0, result.stderr
    train = result.stdout.splitlines()[0].split()
    assert train[0] == "$" and train[2:] == [
        "train_static.py", "--config", "experiments/paper/ant_static.toml", "--folder",
        "results/paper/ant_static_sigma_seed9", "--sigma", "0.05", "--generations", "20", "--seed", "9"]
    evaluate = result.stdout.splitlines()[2]
    assert "--episodes 20 " in evaluate and "results/paper/ant_static_sigma_seed9/" in evaluate
    # a change of the episode's rules trains in them, and is evaluated in the paper's episodes
    result = paper("ant", "static", "--variant", "experiments/static_ant/no_burn_in.toml", "--seed", "9", "--dry-run")
    train, _, evaluate, _ = result.stdout.splitlines()
    assert ("--environment experiments.static_ant.no_burn_in:NoBurnInAntBulletEnv-v0,"
            "experiments.static_ant.no_burn_in:NoBurnInAntAsymRightBulletEnv-v0 ") in train
    assert "--environment AntBulletEnv-v0,AntAsymRightBulletEnv-v0,AntAsymLeftBulletEnv-v0 " in evaluate


def test_the_campaigns_variant_entries_name_files_that_exist():
    from experiments.paper_args import campaign_entries

    variants = [entry.variant for entry in campaign_entries() if entry.variant is not None]
    assert len(variants) == 3 * len(list((ROOT / "experiments" / "static_ant").glob("*.toml")))
    assert all(Path(variant).is_file() for variant in variants)


@pytest.mark.parametrize("text, problem", [
    ("[es\nsigma = 0.05\n", "--variant {file}: "),
    ("[optimiser]\nsigma = 0.05\n", "--variant {file}: optimiser is not a section of an experiment file; valid: es,"),
    ("[es]\nnoise_size = 5\n", "--variant {file}: [es] noise_size is not a setting a flag can change"),
])
def test_a_bad_variant_file_is_refused_in_one_line(tmp_path, text, problem):
    file = tmp_path / "bad.toml"
    file.write_text(text)
    result = paper("ant", "static", "--variant", str(file), "--dry-run")
    assert result.returncode == 2 and result.stdout == ""
    assert len(result.stderr.splitlines()) == 1 and problem.format(file=file) in result.stderr, result.stderr


def test_a_variant_goes_with_a_kind_to_train():
    result = paper("ant", "report", "--variant", SIGMA)
    assert result.returncode == 2 and "--variant goes with an experiment and a kind to train" in result.stderr
    result = paper("campaign", "--budget", "5", "--variant", SIGMA)
    assert result.returncode == 2 and "not --variant" in result.stderr


EPISODES = """
import json, sys

import numpy as np

from envs import make_env, quiet_output

found = []
for environment in sys.argv[1:]:
    with quiet_output():
        env, recipe = make_env(environment)
    env.reset(seed=3)
    steps, height = 0, None
    while True:
        _, _, terminated, truncated, _ = env.step(np.zeros(8))
        steps += 1
        height = float(env.unwrapped.robot.body_xyz[2]) if height is None else height
        if terminated or truncated:
            break
    env.close()
    found.append([recipe.burn_in, steps, height])
print(json.dumps(found))
"""


def episodes(*environments: str) -> list[tuple[int, int, float]]:
    """One episode of zero actions on each environment, in turn, in one process of its own: (burn-in steps, policy
    steps, the torso's height after the first step)."""
    done = subprocess.run([sys.executable, "-c", EPISODES, *environments], cwd=ROOT, env=ENV, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return [tuple(found) for found in json.loads(done.stdout.strip().splitlines()[-1])]


def test_the_studys_episode_rules_change_what_they_name_and_nothing_else():
    no_grace, no_grace_damaged, no_burn_in, paper_after_both = episodes(
        "experiments.static_ant.no_grace:NoGraceAntBulletEnv-v0",
        "experiments.static_ant.no_grace:NoGraceAntAsymRightBulletEnv-v0",
        "experiments.static_ant.no_burn_in:NoBurnInAntBulletEnv-v0", "AntBulletEnv-v0")
    # the paper's: 40 zero-action steps drop the torso to its rest below 0.26 m, the end ignored until step 202; in a
    # process that imported both modules, an ant they did not make keeps the paper's rules
    burn_in, steps, height = paper_after_both
    assert (burn_in, steps) == (40, 202) and height < 0.26
    # no grace: the same rest, the end at the first step
    assert no_grace[:2] == (40, 1) and no_grace_damaged[:2] == (40, 1)
    # no burn-in: the policy's first step is the drop's first (the torso still high), the grace kept
    burn_in, steps, height = no_burn_in
    assert burn_in == 0 and height > 0.7 and steps >= 202


def copy_run(source: Path, runs: Path, name: str) -> Path:
    target = runs / name / source.name
    target.mkdir(parents=True)
    for file in ("config.json", "metrics.csv", "checkpoint.npz"):
        shutil.copy(source / file, target / file)
    return target


def test_the_page_is_a_plain_loop_over_the_runs_files(tmp_path, capsys):
    from es import files

    source = next((ROOT / "results" / "paper" / "ant_static_seed1").glob("*/checkpoint.npz")).parent
    copy_run(source, tmp_path, "ant_static_seed1")
    variant = copy_run(source, tmp_path, "ant_static_one_body_seed3")
    steps = [[242] * 3 + [1040] * 2, [241, 300, 242, 242, 242], [242] * 5]
    bodies = ["AntBulletEnv-v0", "AntAsymRightBulletEnv-v0", "AntAsymLeftBulletEnv-v0"]
    (variant / "evaluation.json").write_text(json.dumps({"environments": [
        {"environment": body, "steps": body_steps, "mean": 10.0 * index}
        for index, (body, body_steps) in enumerate(zip(bodies, steps))]}))
    assert stand.main(["--runs", str(tmp_path)]) == 0
    page = (tmp_path / stand.PAGE_NAME).read_text()
    rows = files.read_metrics(source / "metrics.csv")
    mean = 0.0
    for row in rows[15:20]:  # generations 16 to 20: 200 candidates and the centre, on 2 bodies, less 40 burn-in steps
        mean += (float(row["env_steps"]) / (201 * 2) - 40) / 5
    paper_row = "| paper | none: the paper's settings (the campaign's runs, their first 20 generations) | "
    assert f"{paper_row}1: {mean:.0f} | {int(mean > stand.STANDS)} of 1 | — |" in page
    assert f"| 3: {mean:.0f} | {int(mean > stand.STANDS)} of 1 | seed 3: Ant 2/5 (0.0), AntAsymRight 1/5 (10.0), " \
           "AntAsymLeft 0/5 (20.0) |" in page
    workers = json.loads((source / "config.json").read_text())["workers"]
    core_hours = float(rows[19]["total_seconds"]) * workers / 3600  # the change's run only, to its generation 20
    assert f"The changes' runs took {core_hours:.1f} core-hours" in page
    assert "<!-- runs: paper:1:trained one_body:3:evaluated -->" in page
    assert (tmp_path / stand.FIGURE_NAME).stat().st_size > 0
    # the page behind a run evaluated since: exit 0, saying so; a page edited by hand: exit 1
    (tmp_path / stand.PAGE_NAME).write_text(page.replace("one_body:3:evaluated", "one_body:3:trained"))
    capsys.readouterr()
    assert stand.main(["--runs", str(tmp_path), "--check"]) == 0 and "is behind" in capsys.readouterr().out
    (tmp_path / stand.PAGE_NAME).write_text(page + "edited\n")
    assert stand.main(["--runs", str(tmp_path), "--check"]) == 1


def test_the_result_names_the_changes_that_let_more_seeds_stand():
    assert stand.result({"paper": 1, "sigma": 2}, 3) == "not yet decided, 3 of its 6 runs to come."
    assert stand.result({"paper": 1, "sigma": 1, "one_body": 0}, 0) == (
        "none of the changes lets more of its seeds stand than the paper's settings do (1 of 3).")
    assert stand.result({"paper": 1, "sigma": 2, "one_body": 3, "no_grace": 0}, 0) == (
        "sigma (2 of 3), one_body (3 of 3) let more seeds stand than the paper's settings (1 of 3).")
