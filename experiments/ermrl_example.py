#!/usr/bin/env python
"""ER-MRL's pipeline on CartPole without its velocities: a reservoir evolved for PPO, then PPO with and without it.

    python experiments/ermrl_example.py --record benchmarks/results     # the table of docs/reservoirs.md
    python experiments/ermrl_example.py --nb_trials 2 --HP_training_steps 4096 --training_steps 4096 --seeds 0

Every step is a command of the ported scripts, run in --folder (default runs/ermrl_example), where they keep
their journals, models and logs as they do anywhere; the same command again runs only what is missing. The
steps, in order (--dry-run prints them):

    evolve      scripts/evolve_res.py --h_test del_obs_demo: --nb_trials CMA-ES trials (sampler seed 0), each
                2 PPO lifetimes of --HP_training_steps steps on CartPole-v1 without its velocities (--del_obs True)
    test        scripts/test.py on that study, for each of --seeds: PPO alone, and PPO on the best reservoir at
                three learning rates, --training_steps steps each
    published   scripts/test.py --zero_action True on the same study and the first seed: the reservoir fed a
                zero action, as the published code did (in the folder published_input/, on a copy of the journal)
    zero        scripts/evolve_res.py --zero_action True --h_test del_obs_zero (the same sampler seed), then
                scripts/test.py on it, first seed: evolved and tested with the published input

The results (each model's mean return over the last 10 training episodes, per seed), each study's trials
(the reservoir drawn and its fitness) and each step's minutes are printed, and with --record written as a
record that docs/reservoirs.md renders.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the project's modules, when run as a script

from benchmarks import record as records  # noqa: E402
from cli.errors import Parser, UserError, say  # noqa: E402
from cli.flags import positive_int, seed_value  # noqa: E402
from es.files import atomic_write_text  # noqa: E402
from reservoir_extra import EXTRA_MODULES, INSTALL_HINT, missing_packages  # noqa: E402

ENV_ID = "CartPole-v1"
ACTION_FED, ZERO_ACTION = "del_obs_demo", "del_obs_zero"  # the two studies' --h_test
STUDIES = {ACTION_FED: (), ZERO_ACTION: ("--zero_action", "True")}
BEST_MODEL = "RES_PPO_0.0003"  # the model the published input is compared on
PUBLISHED = "published_input"  # the folder of the test with the published input, on the first study


def parse(argv: list[str]) -> argparse.Namespace:
    parser = Parser(prog="ermrl_example.py", description=__doc__.splitlines()[0],
                    formatter_class=argparse.RawDescriptionHelpFormatter, epilog="\n".join(__doc__.splitlines()[2:]))
    parser.add_argument("--nb_trials", type=positive_int, default=8, help="trials of each study, in all")
    parser.add_argument("--HP_training_steps", type=positive_int, default=20000,
                        help="PPO steps of each lifetime during evolution")
    parser.add_argument("--training_steps", type=positive_int, default=50000, help="PPO steps of each tested model")
    parser.add_argument("--seeds", nargs="+", type=seed_value, default=[0, 1], metavar="SEED",
                        help="the test's seeds; the published input is tested on the first")
    parser.add_argument("--folder", type=records.writable_folder, default=ROOT / "runs" / "ermrl_example",
                        help="where the scripts run and keep their files (made where it is missing)")
    parser.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    parser.add_argument("--record", type=records.writable_folder, default=None, metavar="FOLDER",
                        help="also write the results as a record (benchmarks/record.py, not timed: seeded PPO "
                        "gives the same returns at any load) into FOLDER: benchmarks/results for the docs' table")
    args = parser.parse_args(argv)
    args.folder = args.folder.resolve()
    if len(set(args.seeds)) < len(args.seeds):
        parser.error(f"--seeds {' '.join(map(str, args.seeds))}: each seed once")
    missing = missing_packages(EXTRA_MODULES)
    if missing:
        parser.error(f"the ER-MRL scripts need {', '.join(missing)}, not installed here; {INSTALL_HINT}")
    return args


def script(name: str) -> list[str]:
    return [sys.executable, str(ROOT / "scripts" / f"{name}.py")]


def evolve_command(args: argparse.Namespace, h_test: str, trials: int) -> list[str]:
    return [*script("evolve_res"), "--env_id", ENV_ID, "--h_test", h_test, "--del_obs", "True", "--training_steps",
            str(args.HP_training_steps), "--nb_trials", str(trials), "--nb_seeds", "2", "--sampler", "Cmaes",
            "--sampler_seed", "0", *STUDIES[h_test]]


def test_command(args: argparse.Namespace, h_test: str, seed: int, published: bool = False) -> list[str]:
    return [*script("test"), "--env_id", ENV_ID, "--h_test", h_test, "--HP_training_steps", str(args.HP_training_steps),
            "--training_steps", str(args.training_steps), "--seed", str(seed),
            *(("--zero_action", "True") if published else ())]


class Example:
    """The example's folder: what each step has written there, and the steps that are missing."""

    def __init__(self, args: argparse.Namespace):
        from reservoirs import study  # the extra is there (parse checked)

        self.args, self.study = args, study
        self.clock = args.folder / "minutes.json"  # each step's minutes, over every invocation that ran it

    def minutes(self) -> dict[str, float]:
        return json.loads(self.clock.read_text()) if self.clock.is_file() else {}

    def journal(self, h_test: str) -> Path:
        name = self.study.study_name(ENV_ID, h_test, training_steps=self.args.HP_training_steps)
        return self.args.folder / self.study.journal_path(name)

    def trials(self, h_test: str) -> list:
        """The study's finished trials, in order (none before its journal exists)."""
        import optuna

        path = self.journal(h_test)
        if not path.is_file():
            return []
        name = self.study.study_name(ENV_ID, h_test, training_steps=self.args.HP_training_steps)
        loaded = optuna.load_study(study_name=name, storage=self.study.open_journal(path))
        return [trial for trial in loaded.trials if trial.state == optuna.trial.TrialState.COMPLETE]

    def summary_path(self, h_test: str, seed: int, folder: Path | None = None) -> Path:
        """Where test.py writes its summary (reservoirs.commands.test_models)."""
        return ((folder or self.args.folder) / "models" / self.study.safe_file_name(f"{ENV_ID}_{h_test}")
                / f"test_{self.args.training_steps // 1000}k_steps_seed_{seed}.json")

    def tested(self, h_test: str, summary: Path) -> dict | None:
        """The test's summary, if it tested the study's best trial as it is now; a summary of an earlier best
        (the study has grown since) is not replaced: it stops the example."""
        if not summary.is_file():
            return None
        try:
            found = json.loads(summary.read_text())
            tested = (found["trial"], found["fitness"])
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise UserError(f"{summary} is not a summary test.py wrote ({type(error).__name__}: {error}); move it "
                            "away to test again") from None
        trials = self.trials(h_test)
        best = max(trials, key=lambda trial: trial.value) if trials else None
        if best is None or tested != (best.number, best.value):
            raise UserError(f"{summary} tested trial {found['trial']}, which is not the best trial of the study in "
                            f"{self.journal(h_test)} now; move {summary.parent} away to test it again, or give "
                            "another --folder")
        return found

    def run(self, step: str, command: list[str], cwd: Path) -> None:
        say("$ " + subprocess.list2cmdline(command) + (f"    # in {cwd}" if cwd != self.args.folder else ""))
        if self.args.dry_run:
            return
        started = time.perf_counter()
        done = subprocess.run(command, cwd=cwd)
        if done.returncode:
            sys.exit(done.returncode)
        minutes = self.minutes()
        minutes[step] = minutes.get(step, 0.0) + (time.perf_counter() - started) / 60
        atomic_write_text(self.clock, json.dumps(minutes, indent=1) + "\n")

    def evolve(self, h_test: str) -> None:
        missing = self.args.nb_trials - len(self.trials(h_test))
        if missing > 0:
            self.run(f"evolve {h_test}", evolve_command(self.args, h_test, missing), self.args.folder)

    def test(self, h_test: str, seed: int) -> None:
        if self.args.dry_run or self.tested(h_test, self.summary_path(h_test, seed)) is None:
            self.run(f"test {h_test} seed {seed}", test_command(self.args, h_test, seed), self.args.folder)

    def test_published(self) -> None:
        """The first study's best reservoir fed a zero action, in a folder of its own (test.py's outputs are
        named by the study and seed alone), reading a copy of the study's journal as it is now."""
        folder, seed = self.args.folder / PUBLISHED, self.args.seeds[0]
        if not self.args.dry_run and self.tested(ACTION_FED, self.summary_path(ACTION_FED, seed, folder)) is not None:
            return
        if not self.args.dry_run:
            folder.mkdir(exist_ok=True)
            shutil.copyfile(self.journal(ACTION_FED), folder / self.journal(ACTION_FED).name)
        self.run("published input", test_command(self.args, ACTION_FED, seed, published=True), folder)

    def all(self) -> None:
        if not self.args.dry_run:
            try:
                self.args.folder.mkdir(parents=True, exist_ok=True)
            except OSError as error:
                raise UserError(f"--folder {self.args.folder}: cannot be made ({error.strerror})") from None
        self.evolve(ACTION_FED)
        for seed in self.args.seeds:
            self.test(ACTION_FED, seed)
        self.test_published()
        self.evolve(ZERO_ACTION)
        self.test(ZERO_ACTION, self.args.seeds[0])


def results(example: Example) -> list[tuple[str, str, dict[int, dict]]]:
    """The rows of the results: (measure name, label, seed -> the model's summary entry: its mean return, episodes,
    learning rate). First each model of the first study, then its best reservoir fed the published input, then
    the study evolved with it."""
    args, first = example.args, example.args.seeds[0]
    found: dict[str, dict[int, dict]] = {}
    for seed in args.seeds:
        for model, entry in example.tested(ACTION_FED, example.summary_path(ACTION_FED, seed))["models"].items():
            found.setdefault(model, {})[seed] = entry
    rows = [(model, f"`{model}`", runs) for model, runs in found.items()]
    published = example.tested(ACTION_FED, example.summary_path(ACTION_FED, first, args.folder / PUBLISHED))
    zero = example.tested(ZERO_ACTION, example.summary_path(ZERO_ACTION, first))
    rows.append((f"{BEST_MODEL} published input", f"`{BEST_MODEL}`, same reservoir, `test.py --zero_action True` "
                 "(the published input)", {first: published["models"][BEST_MODEL]}))
    rows.append((f"{BEST_MODEL} {ZERO_ACTION}", f"`{BEST_MODEL}`, evolved and tested with `--zero_action True` "
                 f"(`--h_test {ZERO_ACTION}`)", {first: zero["models"][BEST_MODEL]}))
    return rows


def mean_return(entry: dict) -> float | None:
    return next(value for key, value in entry.items() if key.startswith("mean_return_last_"))


def results_table(rows: list[tuple[str, str, dict[int, dict]]], seeds: list[int]) -> tuple[list[str], list[list[str]]]:
    """Each row's mean return of the last 10 training episodes per seed, with its episodes ("–": not tested)."""
    def cell(entry: dict | None) -> str:
        if entry is None:
            return "–"
        value = mean_return(entry)
        return "no episode finished" if value is None else f"{value:.1f} ({entry['episodes']})"
    return (["model", *(f"seed {seed} (episodes)" for seed in seeds)],
            [[label, *(cell(runs.get(seed)) for seed in seeds)] for _, label, runs in rows])


def trials_table(example: Example) -> tuple[list[str], list[list[str]]]:
    """Both studies' trials side by side: the reservoir each drew (its hyperparameters) and its fitness."""
    studies = {h_test: example.trials(h_test) for h_test in STUDIES}
    names = sorted({name for trials in studies.values() for trial in trials for name in trial.params})
    columns = ["trial", *(f"{h_test}: {name}" for h_test in STUDIES for name in (*names, "fitness"))]
    rows = []
    for number in range(max(len(trials) for trials in studies.values())):
        row = [str(number)]
        for trials in studies.values():
            trial = trials[number] if number < len(trials) else None
            row += [f"{trial.params[name]:.3g}" if trial and name in trial.params else "–" for name in names]
            row.append(f"{trial.value:.2f}" if trial else "–")
        rows.append(row)
    return columns, rows


def markdown(columns: list[str], rows: list[list[str]]) -> str:
    return "\n".join("| " + " | ".join(cells) + " |" for cells in (columns, ["---"] * len(columns), *rows))


def write_record(args: argparse.Namespace, rows: list[tuple[str, str, dict[int, dict]]],
                 tables: dict[str, tuple]) -> None:
    """The results as a record, ``ermrl_example-CartPole-v1`` (docs/reservoirs.md renders its tables): each
    row's mean return per seed, one measure per row of the results."""
    record = records.Record(f"ermrl_example-{ENV_ID}", extra_versions=("stable-baselines3", "optuna", "reservoirpy"),
                            timed=False)
    for name, _, runs in rows:
        values = [value for value in map(mean_return, runs.values()) if value is not None]
        if values:
            record.add(name, f"{name}: mean return of the last 10 training episodes, seeds "
                       f"{', '.join(map(str, runs))}", "", values)
    for name, (columns, cells) in tables.items():
        record.table(name, columns, cells)
    record.note("protocol", {"environment": ENV_ID, "del_obs": True, "nb_trials": args.nb_trials,
                             "HP_training_steps": args.HP_training_steps, "training_steps": args.training_steps,
                             "seeds": args.seeds, "folder": str(args.folder)})
    record.write(args.record)


def main(argv: list[str] | None = None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)
    example = Example(args)
    try:
        example.all()
        if args.dry_run:
            return 0
        rows = results(example)
    except UserError as error:
        print(f"ermrl_example.py: error: {error}", file=sys.stderr)
        return 2
    tables = {"results": results_table(rows, args.seeds), "trials": trials_table(example),
              "minutes": (["step", "minutes"], [[step, f"{value:.1f}"] for step, value in example.minutes().items()])}
    text = "\n\n".join(markdown(*table) for table in tables.values())
    say(text)
    atomic_write_text(args.folder / "results.md", text + "\n")
    if args.record is not None:
        write_record(args, rows, tables)
    return 0


if __name__ == "__main__":
    sys.exit(main())
