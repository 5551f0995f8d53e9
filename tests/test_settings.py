"""One declaration per option (``settings``): what it generates, and run folders of the previous version.

- tests/data/runs_v0 holds three tiny runs made by the code before settings were declared once
  (CartPole-v1, --popsize 4, --generations 2, --seed 1, --threads 1): a static run with --obs_norm
  --obs_clip 5, a Hebbian run with --hebb_rule A --init_weights normal, and a Hebbian run with an
  evolved 5-unit reservoir. The numbers below were recorded with that code: their evaluation (3
  episodes, seeds 0-2) and the sha256 of their last*.dat files once resumed to 3 generations. Their
  config.json files record every setting (hebb_rule for a static run too): they must load and mean
  the same, by the short command the scripts now print and by the original long one.
- config.json, experiment files and flags: unknown keys, keys of another policy kind, missing
  sections and contradicting flags are refused in one line, exit 2, nothing changed.
- --help says each flag once and its default once; the tables and rules come from the declarations.
"""

from __future__ import annotations

import ast
import contextlib
import hashlib
import io
import json
import shutil
from pathlib import Path

import pytest

import evaluate_hebb
import evaluate_static
import train_hebb
import train_static
from cli.config import TrainConfig, declared
from cli.flags import flag_table
from es.files import load_dat
from settings import options
from tests.extras import need

ROOT = Path(__file__).resolve().parent.parent
RUNS = ROOT / "tests" / "data" / "runs_v0"
SCRIPTS = {"static": (train_static, evaluate_static), "hebbian": (train_hebb, evaluate_hebb),
           "reservoir": (train_hebb, evaluate_hebb)}
# recorded with the code before this change (commit f8b9902): evaluation returns, last*.dat hash after a resume
RECORDED = {
    "static": ([8.0, 12.0, 11.0], "4f9d3b8ff593f60e72a70f89aad2558ff2256c321cbd231637998637d0614200"),
    "hebbian": ([18.0, 52.0, 35.0], "9c1e7dfdda1ce86f15ba6f47b5f73ec9c1b4a7d85485b3242ce6c31d52678064"),
    "reservoir": ([17.0, 15.0, 15.0], "20d5c4e03f38c26e42d7d30f6d777fb1d6315598086afc64c6676c8acdac6573"),
}
# the command lines today's hint printed (the old long form), files relative to the run folder
LONG = {
    "static": ["--environment", "CartPole-v1", "--path_weights", "last.dat"],
    "hebbian": ["--environment", "CartPole-v1", "--hebb_rule", "A", "--init_weights", "normal", "--path_hebb",
                "last_coeffs.dat"],
    "reservoir": ["--environment", "CartPole-v1", "--hebb_rule", "A", "--init_weights", "uni", "--reservoir",
                  "--reservoir_units", "5", "--reservoir_seed", "1", "--path_hebb", "last_coeffs.dat",
                  "--path_reservoir", "last_reservoir.dat"],
}


def main(script, *argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = script.main([str(arg) for arg in argv])
        except SystemExit as stop:  # argparse's refusals
            code = stop.code
    return code, out.getvalue(), err.getvalue()


def one_line(code: int, err: str, *named: str) -> str:
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and ": error: " in lines[0], err
    for text in named:
        assert text in lines[0], lines[0]
    return lines[0]


def copy_run(name: str, tmp_path: Path) -> Path:
    run_dir = tmp_path / name
    shutil.copytree(RUNS / name, run_dir)
    return run_dir


def digest(run_dir: Path) -> dict[str, str]:
    return {path.name: hashlib.sha256(path.read_bytes()).hexdigest() for path in sorted(run_dir.iterdir())}


def returns(script, tmp_path: Path, *argv) -> list[float]:
    output = tmp_path / "evaluation.json"
    code, out, err = main(script, *argv, "--episodes", 3, "--json", output)
    assert code == 0, out + err
    return json.loads(output.read_text())["environments"][0]["returns"]


# --- run folders of the previous version -------------------------------------------------------------


@pytest.mark.parametrize("name", list(RECORDED))
def test_a_previous_versions_run_evaluates_to_its_numbers_by_the_short_and_the_long_command(name, tmp_path):
    if name == "reservoir":
        need("reservoirs")
    run_dir = copy_run(name, tmp_path)
    _, evaluate = SCRIPTS[name]
    weights = "last.dat" if name == "static" else "last_coeffs.dat"
    flag = "--path_weights" if name == "static" else "--path_hebb"
    recorded = RECORDED[name][0]
    assert returns(evaluate, tmp_path, flag, run_dir / weights) == recorded
    assert returns(evaluate, tmp_path, flag, run_dir) == recorded  # the folder itself: its last files
    long = [str(run_dir / word) if word.endswith(".dat") else word for word in LONG[name]]
    assert returns(evaluate, tmp_path, *long) == recorded


@pytest.mark.parametrize("name", list(RECORDED))
def test_a_previous_versions_run_resumes_to_its_numbers_and_records_only_its_kinds_settings(name, tmp_path):
    if name == "reservoir":
        need("reservoirs")
    run_dir = copy_run(name, tmp_path)
    train, _ = SCRIPTS[name]
    code, out, err = main(train, "--resume", run_dir, "--generations", 3)
    assert code == 0, out + err
    hashed = hashlib.sha256()
    for path in sorted(run_dir.glob("last*.dat")):
        hashed.update(load_dat(path).tobytes())
    assert hashed.hexdigest() == RECORDED[name][1]
    policy = json.loads((run_dir / "config.json").read_text())["policy"]
    if name == "static":
        assert "hebb_rule" not in policy and "init_weights" not in policy and policy["network"] == "default"
    else:
        assert "network" not in policy and policy["hebb_rule"] == "A"


@pytest.mark.parametrize("fast_conv", [False, True])
def test_a_run_that_recorded_the_retired_fast_conv_resumes_and_evaluates(fast_conv, tmp_path):
    """config.json files of the versions with --fast_conv (before 0.1.0) record it; such a run
    is read as today's (the default CNN, for pixels): it evaluates and resumes to today's numbers."""
    run_dir = copy_run("static", tmp_path)
    config = json.loads((run_dir / "config.json").read_text())
    config["policy"]["fast_conv"] = fast_conv
    (run_dir / "config.json").write_text(json.dumps(config, indent=2))
    assert returns(evaluate_static, tmp_path, "--path_weights", run_dir) == RECORDED["static"][0]
    code, out, err = main(train_static, "--resume", run_dir, "--generations", 3)
    assert code == 0, out + err
    assert hashlib.sha256(load_dat(run_dir / "last.dat").tobytes()).hexdigest() == RECORDED["static"][1]
    assert "fast_conv" not in json.loads((run_dir / "config.json").read_text())["policy"]


def test_a_run_that_recorded_tensorboard_as_a_run_setting_logs_to_tensorboard():
    """Before 0.1.0 TensorBoard was the run's setting ``tensorboard``; such a config.json reads as --logger."""
    config = json.loads((RUNS / "static" / "config.json").read_text())
    assert "log" not in config and config["run"]["tensorboard"] is False
    assert TrainConfig.from_dict(config).log.logger == ()
    config["run"]["tensorboard"] = True
    assert TrainConfig.from_dict(config).log.logger == ("tensorboard",)


# --- config.json ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("edit, named", [
    (lambda config: {key: value for key, value in config.items() if key != "es"}, "has no 'es' section"),
    (lambda config: config | {"es": config["es"] | {"learning_rate": 0.1}}, "unknown settings es.learning_rate"),
    (lambda config: config | {"policy": config["policy"] | {"hebb_rule": "AD"}},
     "policy.hebb_rule (--hebb_rule, for hebbian runs) does not apply to a static run"),
    (lambda config: config | {"run": config["run"] | {"backend": "dask"}}, "--backend must be one of process, ray"),
])
def test_a_config_json_edited_by_hand_is_refused_and_nothing_changes(tmp_path, edit, named):
    run_dir = copy_run("static", tmp_path)
    config = json.loads((run_dir / "config.json").read_text())
    (run_dir / "config.json").write_text(json.dumps(edit(config)))
    before = digest(run_dir)
    code, _, err = main(train_static, "--resume", run_dir, "--generations", 3)
    one_line(code, err, named)
    code, _, err = main(evaluate_static, "--path_weights", run_dir / "last.dat")
    one_line(code, err, named)
    assert digest(run_dir) == before


def test_a_config_json_records_the_settings_of_its_kind_and_reads_back_the_same():
    for name in RECORDED:
        config = TrainConfig.from_dict(json.loads((RUNS / name / "config.json").read_text()))
        again = TrainConfig.from_dict(json.loads(json.dumps(config.to_dict())))
        assert again == config
    static = TrainConfig.from_dict(json.loads((RUNS / "static" / "config.json").read_text()))
    assert set(static.to_dict()["policy"]) == {item.name for item in options(type(static.policy))} - {
        "hebb_rule", "init_weights", "distribution"}


# --- evaluation reads the run --------------------------------------------------------------------------


def test_a_flag_that_contradicts_the_run_is_refused_naming_both_values(tmp_path):
    run_dir = copy_run("hebbian", tmp_path)
    code, _, err = main(evaluate_hebb, "--path_hebb", run_dir / "last_coeffs.dat", "--hebb_rule", "ABCD_lr",
                          "--init_weights", "normal")
    one_line(code, err, "--hebb_rule ABCD_lr (the run has A)", "leave the flags out")
    assert "--init_weights" not in err  # given, but the value the run has
    code, _, err = main(evaluate_hebb, "--path_hebb", run_dir / "last_coeffs.dat", "--path_coev",
                          run_dir / "last_coeffs.dat")
    one_line(code, err, "--path_coev", "this policy has no such file")
    code, _, err = main(evaluate_static, "--path_weights", run_dir / "last_coeffs.dat")
    one_line(code, err, "is from a hebbian run", "evaluate_hebb.py")


def test_evaluation_on_another_environment_than_the_runs_is_allowed(tmp_path):
    run_dir = copy_run("static", tmp_path)
    assert len(returns(evaluate_static, tmp_path, "--path_weights", run_dir, "--environment", "CartPole-v0")) == 3


# --- experiment files ----------------------------------------------------------------------------------


@pytest.mark.parametrize("script, toml, named", [
    (train_static, '[run]\nfolder = ""', '--folder must be a non-empty string'),
    (train_static, '[run]\nbackend = "dask"', "--backend must be one of process, ray, got 'dask'"),
    (train_static, '[policy]\nhebb_rule = "AD"', "policy.hebb_rule (--hebb_rule, for hebbian runs) does not apply"),
    (train_hebb, '[policy]\nnetwork = "small"', "policy.network (--network, for static runs) does not apply"),
    (train_static, '[env]\nenv_ids = ["CartPole-v1"]', "unknown settings env.env_ids"),
    (train_static, '[es]\nbeta1 = 0.5', "--beta1 has an effect only with --strategy openai --optimizer adam; add "
                                         "--optimizer adam or leave --beta1 out"),
    (train_static, '[extra]\na = 1', "unknown settings [extra]"),
])
def test_an_experiment_file_key_the_script_does_not_take_is_refused(tmp_path, monkeypatch, script, toml, named):
    (tmp_path / "x.toml").write_text(toml + "\n")
    monkeypatch.chdir(tmp_path)  # where a run would go if the file's folder were taken
    folder = [] if "folder" in toml else ["--folder", tmp_path / "runs"]
    code, _, err = main(script, "--environment", "CartPole-v1", "--generations", 1, "--popsize", 4, "--config",
                          tmp_path / "x.toml", *folder)
    one_line(code, err, named)
    assert sorted(path.name for path in tmp_path.iterdir()) == ["x.toml"]


def test_an_experiment_file_says_none_where_the_flag_takes_none(tmp_path):
    """TOML has no null: where a flag takes ``none`` (--pgpe_max_sigma_change none: no limit), the file's
    string "none" means the same; elsewhere a string stays a value of the wrong type."""
    experiment = tmp_path / "x.toml"
    experiment.write_text('[es]\nstrategy = "pgpe"\npgpe_max_sigma_change = "none"\n')
    assert TrainConfig.from_toml(experiment).value("pgpe_max_sigma_change") is None
    experiment.write_text('[es]\nstrategy = "pgpe"\npgpe_max_sigma_change = "None"\n')
    assert TrainConfig.from_toml(experiment).value("pgpe_max_sigma_change") is None
    for text, problem in (('pgpe_max_sigma_change = "nothing"', "--pgpe_max_sigma_change must be a number or none, "
                                                                  "got 'nothing'"),
                          ('popsize = "none"', "--popsize must be a whole number, got 'none'")):
        experiment.write_text(f'[es]\nstrategy = "pgpe"\n{text}\n')
        with pytest.raises(ValueError, match=problem):
            TrainConfig.from_toml(experiment)


def test_a_setting_of_another_kind_is_not_a_flag_of_the_script(tmp_path):
    code, _, err = main(train_static, "--environment", "CartPole-v1", "--hebb_rule", "A", "--folder", tmp_path)
    one_line(code, err, "unrecognized arguments: --hebb_rule")
    code, _, err = main(evaluate_hebb, "--path_hebb", "x.dat", "--network", "small")
    one_line(code, err, "unrecognized arguments: --network")


# --- what the declarations generate --------------------------------------------------------------------


@pytest.mark.parametrize("script", [train_static, train_hebb, evaluate_static, evaluate_hebb])
def test_help_shows_each_flag_once_with_its_default_once(script, capsys):
    parser = script.build_parser()
    rows = flag_table(parser)
    flags = [flag for row in rows for flag in row[0].split(", ")]
    assert len(flags) == len(set(flags))
    for flags_text, _, help_text in rows:
        assert help_text.count("(default:") <= 1, (flags_text, help_text)
    text = parser.format_help()
    assert text.count("(default:") == sum("(default:" in row[2] for row in rows)


def test_the_original_flags_are_all_there():
    """Every flag (docs/original.md, "Command lines") of the four original scripts, and pytorch-es's --useAdam."""
    original = {
        train_hebb: ["--environment", "--hebb_rule", "--popsize", "--lr", "--decay", "--sigma", "--init_weights",
                     "--print_every", "--generations", "--threads", "--folder", "--distribution"],
        evaluate_hebb: ["--environment", "--hebb_rule", "--init_weights", "--path_hebb", "--path_coev"],
        train_static: ["--environment", "--popsize", "--print_every", "--lr", "--decay", "--sigma", "--generations",
                       "--folder", "--threads", "--useAdam"],
        evaluate_static: ["--environment", "--path_weights", "--render"],
    }
    for script, flags in original.items():
        known = {flag for row in flag_table(script.build_parser()) for flag in row[0].split(", ")}
        assert set(flags) <= known, set(flags) - known


def test_resumable_and_requires_come_from_the_declarations(tmp_path):
    resumable = {item.name for item in declared() if item.spec.resumable}
    assert resumable == {"generations", "threads", "backend", "ray_address", "print_every", "logger", "wandb_project",
                         "mlflow_uri", "mlflow_experiment"}
    run_dir = copy_run("static", tmp_path)
    code, _, err = main(train_static, "--resume", run_dir, "--lr", "0.3", "--generations", 3)
    one_line(code, err, "--lr 0.3 (the run has 0.2)", "only --generations, --print_every, --threads")
    code, _, err = main(train_static, "--environment", "CartPole-v1", "--reservoir_units", "5", "--folder", tmp_path)
    one_line(code, err, "--reservoir_units has an effect only with --reservoir")


def test_the_optimisers_do_not_import_the_settings():
    tree = ast.parse((ROOT / "es" / "optimizers.py").read_text())
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert not any(module and "settings" in module for module in imported)  # es.exact, its arithmetic, it may
