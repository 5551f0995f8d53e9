"""What the docs say is what runs: every shell command of the code blocks of README.md,
experiments/README.md and docs/*.md runs, for real, with its budget shrunk; the flag tables are what the
parsers say.

Each page runs in a temporary folder holding a view of the checkout (symbolic links to its files), so a
command runs as from the repository root while everything it writes stays in the folder. The commands of
a page run in order: ``<run>`` is the newest run folder a command above made in the folder named before
it. ``<!-- not run: REASON -->`` above a block: its commands are parsed by their scripts' parsers, not
run. ``<!-- files: NAME=PATH -->`` above a block: a file the block names is a copy of PATH. The
conventions are described in docs/development.md.

A script runs in a process forked from a server that has already imported torch and the project (what
costs most of a command's start here), with the command's argv, folder and output: the script itself
runs as ``python SCRIPT ...`` would run it.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import csv
import glob
import importlib.util
import io
import json
import os
import re
import runpy
import select
import shlex
import shutil
import signal
import subprocess
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from unittest import mock

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", ROOT / "experiments" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELLS = ("bash", "sh", "shell", "console")
DIRECTIVE = re.compile(r"<!-- (not run|files): (.*?) -->")  # a line of its own, just above a block
PYTHONS = ("python", "python3")
TIMEOUT = 300
# what the scripts import, loaded once by the server that starts them (a module missing here is left out)
PRELOAD = ("torch", "numba", "scipy", "gymnasium", "pygame", "Box2D", "mujoco", "pybullet", "matplotlib.figure",
           "matplotlib.backends.backend_agg", "matplotlib.font_manager", "cli", "envs", "es", "policies", "report")

spec = importlib.util.spec_from_file_location("docs_generate", ROOT / "docs" / "generate.py")
generate = importlib.util.module_from_spec(spec)
spec.loader.exec_module(generate)
number = generate.records_files.number

# extra -> (modules it installs, how to tell a command needs it)
EXTRAS = {
    "reservoirs": (("reservoirpy", "stable_baselines3", "optuna", "cmaes"),
                   lambda script, args: script.startswith("scripts/") or "--reservoir" in args
                   or script.endswith("ermrl_example.py")),
    "ray": (("ray",), lambda script, args: "ray" in args or "--ray" in args or "ray_vs_process" in script),
    "atari": (("ale_py",), lambda script, args: any(re.search(r"ALE/|NoFrameskip|Deterministic-v|pong", word)
                                                     for word in args)),
    "tensorboard": (("tensorboard",),
                    lambda script, args: "--tensorboard" in args or "tensorboard" in logged(args)
                    or script.startswith("scripts/test")),
    "wandb": (("wandb",), lambda script, args: "wandb" in logged(args)),
    "mlflow": (("mlflow", "sqlalchemy", "alembic"), lambda script, args: "mlflow" in logged(args)),
    "strategies": (("cmaes",), lambda script, args: any("cma_es" in word for word in args)
                   or (script.endswith("strategies.py") and "--strategies" not in args)),  # its defaults: sep_cma_es
    "stats": (("rliable", "arch", "pandas"),
              lambda script, args: script.endswith(("report_runs.py", "benchmarks/strategies.py"))
              or (script.endswith("paper.py") and "report" in args)),
    "bench": (("evotorch",), lambda script, args: "evotorch" in Path(script).name),
}


def logged(args: list[str]) -> list[str]:
    """The trackers a command's --logger names."""
    if "--logger" not in args:
        return []
    following = args[args.index("--logger") + 1:]
    return following[:next((i for i, word in enumerate(following) if word.startswith("--")), len(following))]


# budgets: flag -> tiny value
SHRINK = {"--generations": "1", "--popsize": "2", "--episodes": "1", "--eval_episodes": "1", "--eval_every": "1",
          "--training_steps": "64", "--training_timesteps": "64", "--HP_training_steps": "64", "--nb_trials": "1",
          "--nb_seeds": "1", "--seeds": "1", "--rounds": "1", "--steps": "20", "--budget": "300"}
TRAIN_SCRIPTS = ("train_static.py", "train_hebb.py")
EXPERIMENT_SCRIPTS = ("experiments/paper.py", "experiments/reservoir_front/compare.py")
ERMRL_EXAMPLE = "experiments/ermrl_example.py"  # its defaults are the docs' measurement: shrunk as a training script
RECORDING_SCRIPTS = ("experiments/reservoir_front/compare.py", ERMRL_EXAMPLE)  # --record FOLDER
# documented commands that fail for a known reason being fixed elsewhere
# what a page's folder must not link to: the outputs commands write
OUTPUTS = {".git", ".venv", "runs", "weights", "heb_coeffs", "logs", "models", "__pycache__", ".pytest_cache"}


# --- the commands of the pages ---------------------------------------------------------------------


@dataclass
class Command:
    page: Path
    line: int
    words: list[str]
    not_run: str | None = None
    files: dict[str, str] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def block_commands(page: Path, start: int, lines: list[str], directives: dict) -> list[Command]:
    """The commands of one code block: continuation lines joined, comments dropped."""
    commands, pending, first = [], "", None
    for number, line in enumerate(lines, start):
        if not pending and (not line.strip() or line.lstrip().startswith("#")):
            continue
        first = first or number
        pending += line.rstrip()
        if pending.endswith("\\"):
            pending = pending[:-1] + " "
            continue
        words = shlex.split(pending, comments=True)
        files = dict(item.split("=", 1) for item in directives.get("files", "").split())
        commands.append(Command(page, first, words, directives.get("not run"), files))
        pending, first = "", None
    return commands


def page_commands(page: Path) -> list[Command]:
    commands, directives, block, start, language = [], {}, None, 0, ""
    for number, line in enumerate(page.read_text().splitlines(), 1):
        if block is not None:
            if line.startswith("```"):
                commands += block_commands(page, start, block, directives) if language in SHELLS else []
                block, directives = None, {}
            else:
                block.append(line)
        elif line.startswith("```"):
            block, start, language = [], number + 1, line[3:].strip()
        elif match := DIRECTIVE.fullmatch(line.strip()):
            directives[match[1]] = match[2]
        elif line.strip():
            directives = {}
    return commands


COMMANDS = [command for page in PAGES for command in page_commands(page)]


def parts(words: list[str]) -> list[list[str]]:
    """``a && b``: the commands it chains."""
    chained, current = [], []
    for word in words:
        if word == "&&":
            chained.append(current)
            current = []
        else:
            current.append(word)
    return [*chained, current]


def is_python(word: str) -> bool:
    return Path(word).name in PYTHONS


def needed_extra(script: str, args: list[str]) -> str | None:
    for extra, (modules, needs) in EXTRAS.items():
        if needs(script, args) and any(importlib.util.find_spec(module) is None for module in modules):
            return extra
    return None


def skip_without_extra(script: str, args: list[str]) -> None:
    extra = needed_extra(script, args)
    if extra is not None:
        pytest.skip(f"needs the {extra} extra: pip install -r requirements-{extra}.txt")


# --- the scripts' parsers --------------------------------------------------------------------------


class Captured(Exception):
    def __init__(self, parser: argparse.ArgumentParser):
        self.parser = parser


def captured_parser(script: str) -> argparse.ArgumentParser:
    """The parser of a script that builds it inside its main(): the script runs up to its parse_args."""
    def capture(parser, args=None, namespace=None):
        raise Captured(parser)

    original, argv, path = argparse.ArgumentParser.parse_args, sys.argv, list(sys.path)
    argparse.ArgumentParser.parse_args, sys.argv = capture, [script]
    sys.path.insert(0, str((ROOT / script).parent))  # as python does: the script's folder first
    try:
        runpy.run_path(str(ROOT / script), run_name="__main__")
    except Captured as captured:
        return captured.parser
    finally:
        argparse.ArgumentParser.parse_args, sys.argv, sys.path[:] = original, argv, path
    raise AssertionError(f"{script} built no argparse parser")


def parser_of(script: str) -> argparse.ArgumentParser:
    if "/" not in script or script.startswith("scripts/"):
        return generate.parsers.parser_of(script)
    return captured_parser(script)


def check_parses(script: str, args: list[str]) -> None:
    """``script args`` parse with the script's own parser (compare.py: its training flags after ``--``
    with the training scripts')."""
    if not (ROOT / script).is_file():
        pytest.fail(f"{script}: no such script in the repository")
    if script.startswith("scripts/"):
        skip_without_extra(script, args)  # their parsers import the extra
    checks = [(script, args)]
    if "--" in args and script.endswith("compare.py"):
        checks = [(script, args[:args.index("--")]), *((train, args[args.index("--") + 1:]) for train in TRAIN_SCRIPTS)]
    if "--" in args and script.endswith("seeds.py"):  # its own flags, then a training command
        after = args[args.index("--") + 1:]
        checks = [(script, args[:args.index("--")]), (after[0], after[1:])]
    for name, words in checks:
        errors = io.StringIO()
        with contextlib.redirect_stderr(errors), contextlib.redirect_stdout(io.StringIO()):
            try:
                parser_of(name).parse_args(words)
            except SystemExit as exit:
                if exit.code:
                    pytest.fail(f"{shlex.join([name, *words])}: {errors.getvalue().strip()}")


def check_statically(words: list[str]) -> None:
    """A command that does not run here: each of its parts is what it looks like."""
    for part in parts(words):
        program = Path(part[0]).name
        if program == "xvfb-run":
            check_statically(part[part.index("--") + 1:])
        elif program == "pip" or part[1:3] == ["-m", "pip"]:
            for index, word in enumerate(part):
                if word == "-r":
                    assert (ROOT / part[index + 1]).is_file(), f"{shlex.join(part)}: no {part[index + 1]}"
        elif is_python(program) and part[1] == "-m":
            assert part[2] in ("venv", "pytest"), f"{shlex.join(part)}: which module?"
            if part[2] == "pytest":
                assert all((ROOT / word).exists() for word in pytest_paths(part[3:])), shlex.join(part)
        elif is_python(program):
            check_parses(part[1], placeholders_as_values(part[2:]))
        elif program == "ray":
            assert part[1] in ("start", "stop", "status"), shlex.join(part)
        elif program != "git":
            pytest.fail(f"{shlex.join(part)}: the suite cannot check this command; say how in tests/test_docs.py")


PYTEST_VALUES = {"-n", "-k", "-m", "-p", "--durations"}  # the pytest options the docs give that take a value


def pytest_paths(args: list[str]) -> list[str]:
    """The paths among pytest's arguments: neither options nor their values."""
    return [word for before, word in zip(["", *args], args) if not word.startswith("-") and before not in PYTEST_VALUES]


def placeholders_as_values(args: list[str]) -> list[str]:
    return [re.sub(r"<[a-z ]+>", "x", word) for word in args]


# --- running a command -----------------------------------------------------------------------------


def run_script(argv: list[str], cwd: str, log: str) -> None:
    """In a forked process: run ``python argv...`` in ``cwd``, its output to ``log``, and exit as it does."""
    code = 1
    try:
        output = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(output, 1)
        os.dup2(output, 2)
        os.dup2(os.open(os.devnull, os.O_RDONLY), 0)
        sys.stdout = io.TextIOWrapper(io.FileIO(1, "wb", closefd=False), line_buffering=True)
        sys.stderr = io.TextIOWrapper(io.FileIO(2, "wb", closefd=False), line_buffering=True)
        os.chdir(cwd)
        sys.argv = list(argv)
        sys.path.insert(0, str(Path(argv[0]).parent))
        runpy.run_path(argv[0], run_name="__main__")
        code = 0
    except SystemExit as exit:
        code = exit.code if isinstance(exit.code, int) else (0 if exit.code is None else 1)
        if not isinstance(exit.code, int | None):
            print(exit.code, file=sys.stderr)
    except BaseException:
        traceback.print_exc()
    finally:
        atexit._run_exitfuncs()  # what the interpreter does at exit (Ray's shutdown, pools)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def serve() -> None:
    """The launcher's server (``python tests/test_docs.py``): import what the scripts import, then for each
    request line ``[argv, cwd, log]`` fork a process that runs it; answer its pid, then its exit code."""
    sys.path.insert(0, str(ROOT))
    for module in PRELOAD:
        with contextlib.suppress(ImportError):
            importlib.import_module(module)
    while line := sys.stdin.readline():
        argv, cwd, log = json.loads(line)
        pid = os.fork()
        if pid == 0:
            os.setpgid(0, 0)  # its own process group, which a timeout ends whole
            run_script(argv, cwd, log)
        print(pid, flush=True)
        print(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]), flush=True)


def read_line(stream, timeout: float) -> str | None:
    """A line from the server, unbuffered (so that select sees what is left), or None after ``timeout``."""
    data, deadline = b"", time.monotonic() + timeout
    while not data.endswith(b"\n"):
        if not select.select([stream], [], [], max(0.0, deadline - time.monotonic()))[0]:
            return None
        chunk = os.read(stream.fileno(), 1)
        assert chunk, "the launcher's server stopped"
        data += chunk
    return data.decode()


@pytest.fixture(scope="session")
def launcher():
    """Start commands from a server that has already imported what every script imports (a cold start
    costs 5 to 10 s here, mostly torch and matplotlib)."""
    server = subprocess.Popen([sys.executable, __file__], stdin=subprocess.PIPE, stdout=subprocess.PIPE, bufsize=0)

    def launch(argv: list[str], cwd: Path, log: Path) -> int:
        server.stdin.write((json.dumps([argv, str(cwd), str(log)]) + "\n").encode())
        pid = int(read_line(server.stdout, TIMEOUT))
        code = read_line(server.stdout, TIMEOUT)
        if code is None:
            os.killpg(pid, signal.SIGKILL)
            read_line(server.stdout, TIMEOUT)
            pytest.fail(f"{shlex.join(argv)} ran longer than {TIMEOUT} s; output:\n{log.read_text()[-3000:]}")
        return int(code)

    yield launch
    server.stdin.close()
    server.wait(timeout=60)


@dataclass
class PageFolder:
    """A page's temporary folder: a view of the checkout, and the runs its commands made, in order."""
    path: Path
    runs: list[Path] = field(default_factory=list)
    done: set[int] = field(default_factory=set)
    skipped: dict[int, str] = field(default_factory=dict)

    def run_folders(self) -> set[Path]:
        found = set()
        for folder, _, files in os.walk(self.path):  # links into the checkout are not followed
            if "config.json" in files and "checkpoint.npz" in files:
                found.add(Path(folder))
        return found

    def newest_run(self, prefix: str) -> Path | None:
        parent = (self.path / prefix).resolve() if prefix else None
        matching = [run for run in self.runs if parent is None or run.parent.resolve() == parent]
        return matching[-1] if matching else None


def page_folder(root: Path) -> PageFolder:
    root.mkdir(parents=True)
    for entry in ROOT.iterdir():
        if entry.name not in OUTPUTS:
            (root / entry.name).symlink_to(entry)
    return PageFolder(root)


@pytest.fixture(scope="session")
def folders(tmp_path_factory):
    made: dict[Path, PageFolder] = {}

    def folder(page: Path) -> PageFolder:
        if page not in made:
            made[page] = page_folder(tmp_path_factory.mktemp("docs") / page.stem)
        return made[page]
    return folder


def fill(word: str, folder: PageFolder, command: Command) -> str:
    """``<run>`` -> the newest run in the folder named before it; /tmp/... -> inside the page's folder."""
    if "<run>" in word:
        prefix = word[:word.index("<run>")].split("=")[-1].rstrip("/")  # --flag=runs/<run> too
        prefix = prefix[1:] if prefix.startswith("/tmp/") else prefix
        run = folder.newest_run(prefix)
        if run is None:
            skipped = [f"line {line}: {why}" for line, why in folder.skipped.items()]
            if skipped:
                pytest.skip(f"no run in {prefix or '.'} to fill <run>: an earlier command was skipped ({skipped[0]})")
            pytest.fail(f"{command.name}: no run made in {prefix or '.'} by a command above fills <run>")
        word = word.replace("<run>", run.name, 1)
    if re.search(r"<[a-z ]+>", word):
        pytest.fail(f"{command.name}: unknown placeholder in {word!r} (only <run> is filled)")
    if word.startswith("/tmp/"):
        word = str(folder.path / word[1:])
    return word


def shrink(script: str, args: list[str], folder: PageFolder) -> list[str]:
    """The command with tiny budgets, run serially and with short episodes, writing inside ``folder``."""
    extra = args[args.index("--"):] if "--" in args else []
    args = args[:len(args) - len(extra)]
    if script.endswith("seeds.py") and extra:  # the training command it launches, shrunk as one
        training = shrink(extra[1], extra[2:], folder)
        at = training.index("--threads")  # the launcher sets it
        extra = ["--", extra[1], *training[:at], *training[at + 2:]]
    shrunk, index = [], 0
    while index < len(args):
        word = args[index]
        if word in SHRINK:
            value = "2" if word == "--generations" and "--resume" in args else SHRINK[word]
            shrunk += [word, value]
            index += 1
            while index < len(args) and not args[index].startswith("--"):
                index += 1  # the old value (several for --seeds)
            continue
        shrunk.append(word)
        index += 1
    serial = "2" if "ray" in args else "1"
    if script in TRAIN_SCRIPTS or script in EXPERIMENT_SCRIPTS:
        shrunk = set_flag(shrunk, "--threads", serial)
    if script in TRAIN_SCRIPTS and "--resume" not in args:  # their defaults are the paper's: 200 x 300
        shrunk += [word for flag in ("--generations", "--popsize") if flag not in args for word in (flag, SHRINK[flag])]
        shrunk += [] if "--max_episode_steps" in args else ["--max_episode_steps", "50"]
    if script == ERMRL_EXAMPLE:
        shrunk += [word for flag in ("--nb_trials", "--HP_training_steps", "--training_steps", "--seeds")
                   if flag not in args for word in (flag, SHRINK[flag])]
    if (script in EXPERIMENT_SCRIPTS or script == ERMRL_EXAMPLE) and "--folder" not in args:  # their default
        shrunk += ["--folder", str(folder.path / "runs" / Path(script).stem)]  # folder is in the checkout
    if script in RECORDING_SCRIPTS and "--record" in args:  # a shrunk run's record is no record
        shrunk = set_flag(shrunk, "--record", str(folder.path / "records"))
    if script.endswith("compare.py") and "--arms" not in args:
        shrunk += ["--arms", "static"]  # each arm is two processes
    if script.startswith("benchmarks/") and "--results" not in args:  # a shrunk run's record is no record
        shrunk += ["--results", str(folder.path / "records")]
    return shrunk + extra


def set_flag(args: list[str], flag: str, value: str) -> list[str]:
    if flag in args:
        index = args.index(flag)
        return [*args[:index + 1], value, *args[index + 2:]]
    return [*args, flag, value]


def expand(args: list[str], cwd: Path) -> list[str]:
    """The shell's globbing, for ``weights/*CartPole*``."""
    expanded = []
    for word in args:
        if "*" in word:
            matches = sorted(glob.glob(word, root_dir=cwd))
            assert matches, f"{word} matches nothing"
            expanded += matches
        else:
            expanded.append(word)
    return expanded


def bring_files(command: Command, words: list[str], folder: PageFolder) -> None:
    for name, source in command.files.items():
        if name in words and not (folder.path / name).exists():
            shutil.copyfile(folder.path / fill(source, folder, command), folder.path / name)


def run(command: Command, folder: PageFolder, launch) -> None:
    """Run ``command`` for real in the page's folder, after the commands above it."""
    assert len(parts(command.words)) == 1 and is_python(command.words[0]), (
        f"{command.name}: only python commands run here; mark the block <!-- not run: REASON -->")
    script_word, *args = command.words[1:]
    args = [fill(word, folder, command) for word in args]
    check_parses(script_word, placeholders_as_values(args))
    skip_without_extra(script_word, args)
    args = expand(shrink(script_word, args, folder), folder.path)
    bring_files(command, args, folder)
    before = folder.run_folders()
    flag = "--record" if script_word.endswith("compare.py") else "--results"
    records = Path(args[args.index(flag) + 1]) if flag in args else folder.path / "records"
    recorded = len(list(records.glob("*.json")))
    log = folder.path / f"line{command.line}.log"
    code = launch([str(folder.path / script_word), *args], folder.path, log)
    folder.runs += sorted(folder.run_folders() - before, key=lambda path: path.stat().st_mtime)
    assert code == 0, f"{command.name}: {shlex.join([script_word, *args])} exited {code}:\n{log.read_text()[-3000:]}"
    if script_word.startswith("benchmarks/") or (script_word.endswith("compare.py") and "--record" in args):
        assert len(list(records.glob("*.json"))) > recorded, f"{command.name}: wrote no record in {records}"


def run_in_order(command: Command, folders, launch) -> None:
    """Run the page's runnable commands above ``command`` that have not run yet, then ``command``."""
    folder = folders(command.page)
    for earlier in [other for other in COMMANDS if other.page == command.page and other.line <= command.line]:
        if earlier.not_run is not None or earlier.line in folder.done | set(folder.skipped):
            continue
        try:
            run(earlier, folder, launch)
            folder.done.add(earlier.line)
        except pytest.skip.Exception as skip:
            folder.skipped[earlier.line] = str(skip)
            if earlier is command:
                raise
        except BaseException:
            folder.done.add(earlier.line)  # it failed: its own test says so
            if earlier is command:
                raise


# --- the tests -------------------------------------------------------------------------------------


@pytest.mark.parametrize("command", COMMANDS, ids=[command.name for command in COMMANDS])
def test_documented_command(command, folders, launcher):
    if command.not_run is not None:
        check_statically(command.words)
        return
    run_in_order(command, folders, launcher)


def test_readme_begins_with_the_two_commands():
    """The first command installs the base requirements and trains; the second installs them and
    nothing else, then runs exactly the test command CI runs."""
    train, tests = [parts(command.words) for command in COMMANDS[:2]]
    assert train[1][1:] == ["install", "-r", "requirements.txt"]
    assert tests[1][1:] == ["install", "-r", "requirements.txt"]
    assert Path(train[2][1]).name == "train_static.py"
    assert len(tests) == 3 and tests[2][1:] == ["-m", "pytest", "tests", "-q", "-n", "auto"]


def test_flag_tables_match_the_parsers():
    """Each table between flag markers is what docs/generate.py makes from the parsers now."""
    marker = generate.pattern("flags")
    pages = [page for page in generate.pages() if marker.search(page.read_text())]
    assert pages, "no flag table in docs/"
    for page in pages:
        for match in marker.finditer(page.read_text()):
            script, *other = match["words"].split()  # SCRIPT [except OTHER]
            if any(needed_extra(name, []) for name in (script, *other[1:])):
                continue  # the reservoir scripts' parsers need their extra; CI has it
            assert match["text"] == generate.parsers.table(script, other[1] if other else None), (
                f"{page.relative_to(ROOT)}: the table of {script} differs from its parser; run python docs/generate.py")


def test_figures_are_their_records():
    """Each measured figure of README.md, experiments/README.md and docs/ is what docs/generate.py renders from
    its record in benchmarks/results/ now: the record exists, is not marked loaded, has at least 5 rounds; and
    each campaign result is its run's evaluation (or still pending: a run evaluated since is filled in by the
    next python docs/generate.py, and never shown wrong)."""
    for page in generate.pages():
        text = page.read_text()
        try:
            # every marker but the flag tables (test_flag_tables_match_the_parsers, which knows the extras they need)
            rendered = generate.render(text, page, [], [kind for kind in generate.MARKERS if kind != "flags"])
        except generate.FigureError as error:
            pytest.fail(f"{page.relative_to(ROOT)}: {error}")
        assert rendered == text, (
            f"{page.relative_to(ROOT)}: a figure differs from its record or campaign run; run python docs/generate.py")


# a measured speed typed into a page: 9.3×, 505 µs, 4.3 ms per step, 651 steps/s, 2.0 h on 16 workers (a target is
# written "≥ 8×"; "84×84" and "4 × CPUs" are sizes and products)
TYPED_SPEED = re.compile(r"(?<![\d.,])(?<![≥≤<>])(?<![≥≤<>] )\d[\d,]*(?:\.\d+)?(?:×(?![\d·])|x (?:faster|slower)\b"
                         r"|\s?µs\b|\s?ms per\b|\s?steps/s\b|\s?h on \d+ workers)")


def test_no_speed_figure_is_typed_into_a_page():
    """A speed or comparison figure is rendered from a record (a figure marker), never typed: outside markers,
    code and inline code, no page holds one."""
    typed = []
    for page in generate.pages():
        fenced = False
        for number, line in enumerate(page.read_text().splitlines(), 1):
            fenced ^= line.startswith("```")
            text = re.sub(r"`[^`]*`", "", generate.pattern("figure").sub("", line))
            typed += [f"{page.relative_to(ROOT)}:{number}: {match[0]}" for match in TYPED_SPEED.finditer(text)
                      if not fenced]
    assert not typed, "speed figures typed into the docs (render them from records: docs/development.md):\n" + (
        "\n".join(typed))


def a_record(folder: Path, name: str, loaded: bool = False, rounds: int = 5, taken: str = "20260101T000000Z",
             first: float = 9.0) -> Path:
    values = [first + 0.1 * index for index in range(rounds)]
    measure = {"what": "a ratio", "unit": "x", "values": values, "median": values[len(values) // 2], "min": values[0],
               "max": values[-1], "rounds": rounds}
    body = {"command": "python benchmarks/x.py", "commit": "0" * 12, "date": "2026-01-01T00:00:00+00:00",
            "cpu": "AMD EPYC", "cores": 2, "versions": {}, "load_before": 3.5 if loaded else 0.2, "load_after": 0.3,
            "loaded": loaded, "measures": {"env_step": measure}, "notes": {}}
    path = folder / f"{name}-{taken}.json"
    path.write_text(json.dumps(body))
    return path


def test_a_figure_is_rendered_from_its_record_and_checked(tmp_path):
    a_record(tmp_path, "quiet")
    page = ROOT / "docs" / "speed.md"
    text = "stepped <!-- figure:quiet env_step -->10×<!-- end figure --> faster"
    rendered = generate.render(text, page, results=tmp_path)
    link = os.path.relpath(tmp_path / "quiet-20260101T000000Z.json", page.parent)
    assert rendered == f"stepped <!-- figure:quiet env_step -->[9.20× (9.00–9.40), AMD EPYC, 2 cores]({link})" \
                       "<!-- end figure --> faster"
    assert generate.render(rendered, page, results=tmp_path) == rendered  # the check the pages pass


def test_a_figure_is_its_commands_newest_record_taken_on_a_quiet_machine(tmp_path):
    """A page names a record's command, not one record: a newer record of it renders there; a newer one taken on
    a loaded machine does not; a record of another command whose name begins the same is another command's."""
    page = ROOT / "docs" / "speed.md"
    a_record(tmp_path, "quiet")
    a_record(tmp_path, "quiet", taken="20260301T000000Z", first=7.0)
    a_record(tmp_path, "quiet", taken="20260401T000000Z", first=5.0, loaded=True)
    a_record(tmp_path, "quiet-scaling", taken="20260501T000000Z", first=3.0)
    rendered = generate.render("<!-- figure:quiet env_step --><!-- end figure -->", page, results=tmp_path)
    assert "[7.20× (7.00–7.40), AMD EPYC, 2 cores](" in rendered and "quiet-20260301T000000Z.json)" in rendered
    # a newer run of the command that did not measure it (a flag's add-on measure): the newest one that did
    newer = a_record(tmp_path, "quiet", taken="20260601T000000Z", first=2.0)
    body = json.loads(newer.read_text())
    body["measures"] = {"reset": body["measures"].pop("env_step")}
    newer.write_text(json.dumps(body))
    assert generate.render("<!-- figure:quiet env_step --><!-- end figure -->", page, results=tmp_path) == rendered
    assert "quiet-20260601T000000Z.json)" in generate.render("<!-- figure:quiet reset --><!-- end figure -->", page,
                                                            results=tmp_path)


@pytest.mark.parametrize(("kind", "message"), [("loaded", "loaded"), ("short", "3 rounds"), ("missing", "no record"),
                                               ("measure", "no measure 'reset'")])
def test_a_figure_that_cannot_be_published_is_refused(tmp_path, kind, message):
    a_record(tmp_path, "loaded", loaded=True)
    a_record(tmp_path, "short", rounds=3)
    a_record(tmp_path, "measure")
    measure = "reset" if kind == "measure" else "env_step"
    text = f"<!-- figure:{kind} {measure} --><!-- end figure -->"
    with pytest.raises(generate.FigureError, match=message):
        generate.render(text, ROOT / "README.md", results=tmp_path)


def a_table_record(folder: Path, name: str, loaded: bool = False) -> Path:
    path = a_record(folder, name, loaded)
    body = json.loads(path.read_text())
    body["notes"]["results"] = {"columns": ["row", "population", "budget", "σ", "steps", "P"],
                                "rows": [["snes", 64, 1000000, 0.02394, {"value": 20513.4, "low": 15870, "high": 26011},
                                          {"value": 0.625, "low": 0.4, "high": 0.85, "digits": 2}]]}
    path.write_text(json.dumps(body))
    return path


@pytest.mark.parametrize(("text", "message"), [
    ("<!-- figure:car_racing --><!-- end figure -->", "it takes figure:RECORD MEASURE"),
    ("<!-- flags:train_hebb.py but train_static.py -->\n<!-- end flags -->", "it takes flags:SCRIPT [except OTHER]"),
    ("<!-- remaining:campaign --><!-- end remaining -->", "it takes no words"),
])
def test_a_marker_written_wrong_is_refused_naming_what_it_takes(text, message):
    """MARKERS, the one table of marker kinds, says what words each takes; a marker with others is refused."""
    with pytest.raises(generate.FigureError, match=re.escape(message)):
        generate.render(text, ROOT / "README.md")


def test_a_records_table_is_rendered_with_its_intervals_and_machine(tmp_path):
    a_table_record(tmp_path, "solve")
    page = ROOT / "docs" / "strategies.md"
    text = "<!-- table:solve results -->\nold\n<!-- end table -->"
    link = os.path.relpath(tmp_path / "solve-20260101T000000Z.json", page.parent)
    assert generate.render(text, page, results=tmp_path) == (
        "<!-- table:solve results -->\n| row | population | budget | σ | steps | P |\n|---|---|---|---|---|---|\n"
        "| snes | 64 | 1,000,000 | 0.024 | 20,513 [15,870, 26,011] | 0.62 [0.40, 0.85] |\n\n"
        f"[AMD EPYC, 2 cores, 2026-01-01]({link})\n<!-- end table -->")
    a_table_record(tmp_path, "busy", loaded=True)
    with pytest.raises(generate.FigureError, match="loaded"):
        generate.render("<!-- table:busy results -->\n<!-- end table -->", page, results=tmp_path)
    with pytest.raises(generate.FigureError, match="no table 'settings'"):
        generate.render("<!-- table:solve settings -->\n<!-- end table -->", page, results=tmp_path)


def test_a_tables_probabilities_are_said_from_its_record(tmp_path):
    """<!-- intervals:RECORD KEY -->: for each P(X > Y) column, the rows whose interval lies above a half, holds
    one, lies below it (a row without an estimate, the reference, is in none); a table without one is refused."""
    path = a_record(tmp_path, "compare")
    body = json.loads(path.read_text())
    p = [(0.9, 0.6, 1.0), (0.5, 0.2, 0.8), (0.1, 0.0, 0.4), (0.7, 0.5, 0.9)]
    body["notes"]["results"] = {"columns": ["strategy", "IQM", "P(X > a) [95 % CI]"], "rows": [
        ["a", {"value": 3.0, "low": 0.7, "high": 9.0, "digits": 1}, "—"]] + [
        [name, {"value": 1.0, "low": 0.6, "high": 2.0, "digits": 1}, {"value": v, "low": lo, "high": hi, "digits": 2}]
        for name, (v, lo, hi) in zip("bcde", p, strict=True)]}
    body["notes"]["plain"] = {"columns": ["strategy", "IQM"], "rows": [["a", 1.0]]}
    path.write_text(json.dumps(body))
    page = ROOT / "docs" / "strategies.md"
    text = "<!-- intervals:compare results -->old<!-- end intervals -->"
    assert generate.render(text, page, results=tmp_path) == (
        "<!-- intervals:compare results -->The interval of P(X > a) lies above a half for b; holds a half for c and "
        "e; lies below a half for d.<!-- end intervals -->")
    body["notes"]["results"]["rows"] = [row for row in body["notes"]["results"]["rows"] if row[0] in "ce"]
    path.write_text(json.dumps(body))
    assert "holds a half for every strategy." in generate.render(text, page, results=tmp_path)
    with pytest.raises(generate.FigureError, match=re.escape("compare: the table 'plain' has no column P(X > Y)")):
        generate.render("<!-- intervals:compare plain --><!-- end intervals -->", page, results=tmp_path)
    body["notes"]["results"]["rows"][0][2] = {"value": 0.5, "digits": 2}  # an estimate without its interval
    path.write_text(json.dumps(body))
    with pytest.raises(generate.FigureError, match=re.escape("an estimate of P(X > a) [95 % CI] without its interval")):
        generate.render(text, page, results=tmp_path)


@pytest.fixture(scope="module")
def evaluated_runs(tmp_path_factory) -> Path:
    """A folder of campaign runs as experiments/paper.py leaves them: one small CarRacing run, trained and
    evaluated by paper.py itself (config.json, checkpoint, metrics.csv, weights, evaluation.json, frames.png)."""
    runs = tmp_path_factory.mktemp("paper_runs")
    subprocess.run([sys.executable, "experiments/paper.py", "carracing", "hebbian", "--popsize", "4", "--generations",
                    "2", "--episodes", "2", "--threads", "1", "--folder", str(runs / "carracing_hebbian_seed1")],
                   cwd=ROOT, check=True, capture_output=True, timeout=600,
                   env={**os.environ, "SDL_VIDEODRIVER": "dummy"})
    return runs


def test_what_a_run_adds_to_a_clone_is_rendered_from_its_files(evaluated_runs):
    """<!-- weight:RUN -->: the sizes of the files a campaign run commits, its checkpoint per chunk, then its final
    weights and its evaluations and pictures; the headline <!-- headline:RUN --> is its mean ± std, linked."""
    page = ROOT / "experiments" / "README.md"
    (run,) = [path for path in (evaluated_runs / "carracing_hebbian_seed1").iterdir() if path.is_dir()]

    def megabytes(*names: str) -> str:
        return f"{sum((run / name).stat().st_size for name in names) / 1e6:.1f} MB"

    pictures = [name for name in ("evaluation.json", "evaluation_best.json", "adaptation.png", "frames.png")
                if (run / name).is_file()]
    assert generate.render("<!-- weight:carracing_hebbian_seed1 --><!-- end weight -->", page, runs=evaluated_runs) \
        == (f"<!-- weight:carracing_hebbian_seed1 -->each chunk commits its [checkpoint.npz]"
            f"({os.path.relpath(run / 'checkpoint.npz', page.parent)}) ({megabytes('checkpoint.npz')}) beside its "
            f"config.json and metrics.csv; completed, the run adds its final weights "
            f"({megabytes(*(path.name for path in run.glob('last*.dat')))}) and its evaluations and pictures "
            f"({megabytes(*pictures)})<!-- end weight -->")
    (entry,) = json.loads((run / "evaluation.json").read_text())["environments"]
    headline = generate.render("<!-- headline:carracing_hebbian_seed1 --><!-- end headline -->", page,
                               runs=evaluated_runs)
    assert headline == (f"<!-- headline:carracing_hebbian_seed1 -->[**{number(entry['mean'])} ± "
                        f"{number(entry['std'])}**]({os.path.relpath(run / 'evaluation.json', page.parent)})"
                        "<!-- end headline -->")


def test_a_campaign_result_is_rendered_from_its_evaluation(evaluated_runs):
    from report.machine import cpu_model

    page = ROOT / "experiments" / "README.md"
    (run,) = [path for path in (evaluated_runs / "carracing_hebbian_seed1").iterdir() if path.is_dir()]
    (entry,) = json.loads((run / "evaluation.json").read_text())["environments"]
    returns = entry["returns"]
    mean = sum(returns) / len(returns)
    std = (sum((value - mean) ** 2 for value in returns) / len(returns)) ** 0.5  # over the episodes, as numpy's
    with open(run / "metrics.csv", newline="") as handle:
        hours = sum(float(row["seconds"]) for row in csv.DictReader(handle)) / 3600
    evaluation = os.path.relpath(run / "evaluation.json", page.parent)
    text = ("| <!-- result:carracing_hebbian_seed1 -->old<!-- end result --> | "
            "<!-- result:carracing_hebbian_seed1 CarRacing-v3 -->old<!-- end result --> |")
    rendered = generate.render(text, page, runs=evaluated_runs)
    weights = os.path.relpath(run, page.parent)
    cell = (f"**{number(mean)} ± {number(std)}** ([2 episodes on held-out seeds]({evaluation}), "
            f"generation 2 after {number(hours)} h of training on {cpu_model()}, 1 worker, "
            f"[weights]({weights}))")
    assert rendered == (f"| <!-- result:carracing_hebbian_seed1 -->{cell}<!-- end result --> | "
                        f"<!-- result:carracing_hebbian_seed1 CarRacing-v3 -->{cell}<!-- end result --> |")
    assert generate.render(rendered, page, runs=evaluated_runs) == rendered  # the check the pages pass
    # the spread, for 2 episodes written from the definition: numpy's linear percentile is lo + p * (hi - lo)
    lo, hi = sorted(returns)
    floor = 0.75 * mean
    below = sum(value < floor for value in returns)
    spread = (f"median {number(lo + 0.5 * (hi - lo))}, quartiles {number(lo + 0.25 * (hi - lo))}–"
              f"{number(lo + 0.75 * (hi - lo))}, lowest {number(lo)}, highest {number(hi)}; "
              f"{below} of 2 episodes below three quarters of the mean ({number(floor)})")
    marker = "<!-- spread:carracing_hebbian_seed1 CarRacing-v3 -->{}<!-- end spread -->"
    assert generate.render(marker.format("old"), page, runs=evaluated_runs) == marker.format(spread)
    # the lengths, written from the definition for these 2 episodes, and for made-up ones of each form
    steps = entry["steps"]
    expected = (f"every one of its 2 episodes ends at step {steps[0]}" if steps[0] == steps[1]
                else f"its 2 episodes end at steps {min(steps)}–{max(steps)} (median {number(sum(steps) / 2)})")
    marker = "<!-- lengths:carracing_hebbian_seed1 CarRacing-v3 -->{}<!-- end lengths -->"
    assert generate.render(marker.format("old"), page, runs=evaluated_runs) == marker.format(expected)
    made_up = {"steps": [1000, 150, 1000, 997, 400], "returns": [651.0, 79.25, 889.0, 514.0, 200.0]}
    with mock.patch.object(generate.evaluations, "evaluation_of", return_value=(run, {}, made_up)):
        assert generate.evaluations.lengths("x", None, page) == (
            "2 of its 5 episodes last 1000 steps, the longest, and score 651 to 889; the other 3 end at steps 150–997 "
            "(median 400), with a median return of 200")
        made_up["steps"][2] = 999
        assert generate.evaluations.lengths("x", None, page) == "its 5 episodes end at steps 150–1000 (median 997)"
        made_up["steps"] = [3]
        with pytest.raises(generate.FigureError, match="1 episode lengths for 5 returns"):
            generate.evaluations.lengths("x", None, page)
    # an ant's forward distance; a run without one (CarRacing's) is refused, naming the file
    ant = {"forward_mean": 16.61, "forward_std": 0.767, "returns": [1.0], "steps": [1]}
    with mock.patch.object(generate.evaluations, "evaluation_of", return_value=(run, {}, ant)):
        assert generate.evaluations.forward("x", None, page) == "16.6 ± 0.767 m forward"
    with pytest.raises(generate.FigureError, match="holds no forward distance"):
        generate.render("<!-- forward:carracing_hebbian_seed1 --><!-- end forward -->", page, runs=evaluated_runs)
    # the lowest episode: its seed as an offset from 2**31, its return and its length
    worst = min(range(len(returns)), key=returns.__getitem__)
    marker = "<!-- lowest:carracing_hebbian_seed1 -->{}<!-- end lowest -->"
    assert generate.render(marker.format("old"), page, runs=evaluated_runs) == marker.format(
        f"the lowest, on seed 2³¹ + {entry['seeds'][worst] - 2**31}, scores {number(returns[worst])} and ends at "
        f"step {entry['steps'][worst]}")
    # the first episode, the one frames.png shows: its length and its return
    marker = "<!-- first:carracing_hebbian_seed1 -->{}<!-- end first -->"
    assert generate.render(marker.format("old"), page, runs=evaluated_runs) == marker.format(
        f"{entry['steps'][0]} steps, return {number(returns[0])}")
    # the curve: the first generation whose population mean passed each threshold, the last generations' ranges
    with open(run / "metrics.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    means, centres = [float(row["return_mean"]) for row in rows], [float(row["center_return"]) for row in rows]
    marker = "<!-- curve:carracing_hebbian_seed1 -1e9 1e9 -->{}<!-- end curve -->"
    assert generate.render(marker.format("old"), page, runs=evaluated_runs) == marker.format(
        f"the population's mean return passed -1e9 at generation 1 and never 1e9, and stayed between "
        f"{number(min(means))} and {number(max(means))} over the last {len(rows)} generations, while the centre's own "
        f"training episode scored {number(min(centres))} to {number(max(centres))} in them")
    with pytest.raises(generate.FigureError, match="its thresholds are numbers"):
        generate.render("<!-- curve:carracing_hebbian_seed1 high --><!-- end curve -->", page, runs=evaluated_runs)
    # the best centre: the first generation of metrics.csv with the highest centre return, evaluated on the same seeds
    with open(run / "metrics.csv", newline="") as handle:
        top = max(csv.DictReader(handle), key=lambda row: float(row["center_return"]))
    best = json.loads((run / "evaluation_best.json").read_text())
    assert best["weights"] == {"centre": "best", "generation": int(top["generation"]),
                               "training_return": float(top["center_return"])}
    (best_entry,) = best["environments"]
    assert best_entry["seeds"] == entry["seeds"]
    best_cell = (f"**{number(best_entry['mean'])} ± {number(best_entry['std'])}** ([2 episodes on "
                 f"held-out seeds]({os.path.relpath(run / 'evaluation_best.json', page.parent)}), the best centre: "
                 f"training return {number(float(top['center_return']))} at generation {top['generation']})")
    marker = "<!-- best:carracing_hebbian_seed1 CarRacing-v3 -->{}<!-- end best -->"
    assert generate.render(marker.format("old"), page, runs=evaluated_runs) == marker.format(best_cell)
    strip = generate.render("<!-- frames:carracing_hebbian_seed1 --><!-- end frames -->", page, runs=evaluated_runs)
    assert f"]({os.path.relpath(run / 'frames.png', page.parent)})<!-- end frames -->" in strip
    with pytest.raises(generate.FigureError, match=r"no environment CarRacing-v2 in .* \(CarRacing-v3\)"):
        generate.render("<!-- result:carracing_hebbian_seed1 CarRacing-v2 --><!-- end result -->", page,
                        runs=evaluated_runs)


def test_a_campaign_result_not_yet_evaluated_is_pending_and_a_late_page_is_behind(evaluated_runs, tmp_path):
    page = ROOT / "README.md"
    pending = f"<!-- result:carracing_static_seed1 -->{generate.evaluations.PENDING}<!-- end result -->"
    for kind in ("result", "spread", "best"):  # no such run
        marker = f"<!-- {kind}:carracing_static_seed1 -->x<!-- end {kind} -->"
        assert generate.render(marker, page, runs=evaluated_runs) == pending.replace("result", kind)
    shutil.copytree(evaluated_runs / "carracing_hebbian_seed1", tmp_path / "carracing_hebbian_seed1")
    (run,) = [path for path in (tmp_path / "carracing_hebbian_seed1").iterdir() if path.is_dir()]
    (run / "evaluation.json").rename(run / "later.json")  # trained, not yet evaluated
    written = f"<!-- result:carracing_hebbian_seed1 -->{generate.evaluations.PENDING}<!-- end result -->"
    assert generate.render(written, page, runs=tmp_path) == written
    (run / "later.json").rename(run / "evaluation.json")  # evaluated since the page was written
    behind = []
    assert generate.render(written, page, behind, runs=tmp_path) == written  # a check leaves it, and says so
    assert behind == ["carracing_hebbian_seed1"]
    assert generate.evaluations.PENDING not in generate.render(written, page, runs=tmp_path)  # a rewrite fills it in


def test_the_campaigns_remaining_runs_are_rendered_and_a_later_state_is_behind(evaluated_runs):
    """``<!-- remaining -->`` holds the campaign's remaining runs, projected from the runs' files (experiments/cost.py);
    the runs move on at every chunk, so a check leaves a page written before as it is, and names it."""
    from experiments.paper_args import campaign_entries

    page = ROOT / "experiments" / "README.md"
    written = "<!-- remaining -->old<!-- end remaining -->"
    rendered = generate.render(written, page, runs=evaluated_runs)
    # the small run in evaluated_runs is seed 1 of CarRacing Hebbian, 2 of the campaign's 300 generations: no run is
    # complete, so none of the campaign's runs has a completed run of its kind to be projected from
    assert rendered.startswith(f"<!-- remaining -->{len(campaign_entries())} runs to train: not projected, no "
                               "completed run of their kind yet: carracing hebbian seed 1, carracing static seed 1, ")
    assert rendered.endswith(".<!-- end remaining -->")
    behind: list[str] = []
    assert generate.render(written, page, behind, runs=evaluated_runs) == written
    assert behind == ["the campaign's remaining runs"]
    behind = []
    assert generate.render(rendered, page, behind, runs=evaluated_runs) == rendered and behind == []


def test_the_campaigns_report_is_rendered_once_every_evaluated_run_is_in(tmp_path):
    """<!-- report:EXPERIMENT ENVIRONMENT -->: the files experiments/paper.py's report writes (report/stats.py's
    own CSV writer here), pending until each kind has an evaluated run and the report holds every evaluated run
    the campaign plans, then each kind's IQM and mean with their intervals, P(Hebbian > static), and how many
    planned runs are still to come."""
    from dataclasses import asdict, replace

    from report import stats

    assert generate.runs_files.campaign_folders("carracing") == {
        kind: {f"carracing_{kind}_seed{seed}" for seed in (1, 2, 3, 4, 5)} for kind in ("hebbian", "static")}
    page = ROOT / "README.md"
    folder = tmp_path / "carracing_report" / "CarRacing-v3"
    planned = {kind: {f"carracing_{kind}_seed{seed}" for seed in (1, 2, 3)} for kind in ("static", "hebbian")}

    def rendered() -> str:
        return generate.runs_files.report("carracing", "CarRacing-v3", page, tmp_path, planned)

    def evaluate(*names: str) -> None:
        for name in names:
            run = tmp_path / name / "20261201-000000_CarRacing-v0"
            run.mkdir(parents=True)
            (run / "checkpoint.npz").write_bytes(b"")  # (a run folder is one with a checkpoint)
            (run / "evaluation.json").write_text("{}")

    assert rendered() == generate.runs_files.REPORT_PENDING  # no report yet
    folder.mkdir(parents=True)
    summaries = [stats.Summary("static", 2, 840.25, 830.5, 850.0, 841.0, 829.0, 852.75, 840.25),
                 stats.Summary("hebbian", 2, 866.75, 860.0, 873.5, 866.75, 860.0, 873.5, 866.75)]
    (folder / "summary.csv").write_text(stats.csv_text([asdict(summary) for summary in summaries]))
    (folder / "improvement.csv").write_text(stats.csv_text([asdict(stats.Improvement("static", "hebbian", 0.25, 0.0,
                                                                                     0.75)),
                                                            asdict(stats.Improvement("hebbian", "static", 0.75, 0.25,
                                                                                     1.0))]))

    def scores(*folders: str) -> None:
        (folder / "scores.csv").write_text(stats.csv_text([{"group": name.split("_")[1], "run": f"{name}/2026_run",
                                                            "score": 1.0} for name in folders]))

    scores("carracing_static_seed1", "carracing_hebbian_seed1", "carracing_hebbian_seed2")
    assert rendered() == generate.runs_files.REPORT_PENDING  # no run evaluated yet
    evaluate("carracing_static_seed1", "carracing_static_seed2", "carracing_hebbian_seed1", "carracing_hebbian_seed2")
    assert rendered() == generate.runs_files.REPORT_PENDING  # static seed 2 is evaluated, but not in the report yet
    scores("carracing_static_seed1", "carracing_static_seed2", "carracing_hebbian_seed1", "carracing_hebbian_seed2")
    summary = os.path.relpath(folder / "summary.md", page.parent)
    assert rendered() == ("over 2 runs of each kind (95 % bootstrap intervals): static IQM **840** [830, 850], mean "
                          "**841** [829, 853]; Hebbian IQM **867** [860, 874], mean **867** [860, 874]; "
                          f"P(Hebbian > static) **0.75** [0.25, 1.00] ([the report]({summary})); 2 more runs of the "
                          "campaign to come")
    evaluate("carracing_static_seed3")
    assert rendered() == generate.runs_files.REPORT_PENDING  # evaluated since the report was written
    written = f"<!-- report:carracing CarRacing-v3 -->{generate.runs_files.REPORT_PENDING}<!-- end report -->"
    behind = []  # the campaign's own plan's runs are not in tmp_path: still pending, not behind
    assert generate.render(written, page, behind, runs=tmp_path) == written and behind == []
    # one run per kind, every planned one in: no interval (every resample is that run), as the report itself says
    planned = {kind: {f"carracing_{kind}_seed1"} for kind in ("static", "hebbian")}
    (folder / "summary.csv").write_text(stats.csv_text([asdict(replace(summary, runs=1)) for summary in summaries]))
    assert rendered() == ("over 1 run of each kind: static IQM **840** (no interval: 1 run), mean **841** (no "
                          "interval: 1 run); Hebbian IQM **867** (no interval: 1 run), mean **867** (no interval: "
                          f"1 run); P(Hebbian > static) **0.75** (no interval: 1 run) ([the report]({summary}))")
    (folder / "improvement.csv").write_text(stats.csv_text([asdict(stats.Improvement("static", "hebbian", 0.25, 0.0,
                                                                                     0.75))]))
    with pytest.raises(generate.FigureError, match="not a report of both kinds"):
        rendered()


def test_a_record_of_counts_is_never_loaded(tmp_path, monkeypatch):
    """Steps to solve from seeded runs do not move with the load: such a record (timed=False) keeps its load
    but is not marked loaded; a timed one taken at the same load is."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import record as records

    monkeypatch.setattr(records, "load", lambda: 9.0)
    for timed in (False, True):
        made = records.Record(f"counts{timed}", timed=timed)
        made.add("steps", "steps to solve", "steps", [1, 2, 3, 4, 5])
        body = json.loads(made.write(tmp_path).read_text())
        assert body["timed"] is timed and body["loaded"] is timed and body["load_before"] == 9.0


def test_every_benchmark_writes_a_record():
    """Each script of benchmarks/ takes --results (benchmarks/record.py writes its record there)."""
    scripts = sorted(path for path in (ROOT / "benchmarks").glob("*.py") if path.name != "record.py")
    assert scripts
    for script in scripts:
        source = script.read_text()
        assert "add_results_flag(parser)" in source and ".write(args.results)" in source, (
            f"{script.relative_to(ROOT)} writes no record (benchmarks/record.py)")


def table_commands() -> list[tuple[str, list[str]]]:
    """The commands of the pages' tables (a measured figure's, an original command line's): inline code
    that runs one of this repository's scripts."""
    found = []
    for page in PAGES:
        for number, line in enumerate(page.read_text().splitlines(), 1):
            for span in re.findall(r"`((?:\.venv/bin/)?python3? [^`]+)`", line) if line.startswith("|") else []:
                words = shlex.split(span)
                if (ROOT / words[1]).is_file() and not re.search(r"\$|\.\.\.", span):  # not templates of SLURM lines
                    found.append((f"{page.relative_to(ROOT)}:{number}", words))
    return found


@pytest.mark.parametrize(("where", "words"), table_commands(), ids=[where for where, _ in table_commands()])
def test_table_command_parses(where, words):
    """A command in a table is not run (those are measurements, or the original's lines), but it parses."""
    skip_without_extra(words[1], words[2:])  # a parser may import its extra
    check_parses(words[1], placeholders_as_values(words[2:]))


def test_no_command_outside_a_code_block():
    """An indented block is a code block too, but the suite only reads fenced ones."""
    for page in PAGES:
        fenced = False
        for number, line in enumerate(page.read_text().splitlines(), 1):
            fenced ^= line.startswith("```")
            assert fenced or not re.match(r" {4}(\.venv/bin/)?python3? \S+\.py", line), (
                f"{page.relative_to(ROOT)}:{number}: a command in an indented block; fence it with ```bash")


if __name__ == "__main__":
    serve()


def test_pages_name_a_records_command_not_one_record():
    """A figure or table marker names the command whose newest record it renders (``figure:car_racing ...``), never
    one record by its time (``car_racing-20261127T223326Z``), so a new record updates every page that shows it."""
    stamped = re.compile(r"<!-- (?:figure|table):[\w.-]*-\d{8}T\d{6}Z ")
    pages = [ROOT / "README.md", ROOT / "experiments" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    assert [page.name for page in pages if stamped.search(page.read_text())] == []
