"""The plug-in points (``plugins``): the five examples of docs/how-it-works.md, "Plug-in points", added to a copy
of the project exactly as the page writes them (each module, and each registry line), then trained with; and the
registry mechanism itself.

A code block of that section is placed by the paragraph above it, which ends with a colon and names its file
first: a file the project lacks is written with the block; a file it has (a registry) gets the block's lines,
an import line replacing the one that imports from the same package, any other line added last to the
registry's list. The copy then trains, in one process, a run of each: the random-search strategy with the JSON
lines logger, the linear policy kind through its own scripts, the linear network through train_static.py, and
the recipe's environment; the files those runs leave say each plug-in did what the page says.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from cli.config import declared
from es.files import read_metrics
from es.settings import ESSettings, SearchSettings
from plugins import Plugin, Registry, joined
from settings import check, options, setting

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "how-it-works.md"
COPIED = ("cli", "envs", "es", "policies", "report", "damaged_bullet_morphologies")
FIRST_PATH = re.compile(r"`([\w/.]+\.py)`")

# the recipe example's environment class, which the page leaves to the reader ("beside your environment's class"):
# every step is a negative reward, so the recipe's early stop (stop_patience=30) ends each episode at step 31
WALKER = '''
import gymnasium as gym
import numpy as np


class Walker1D(gym.Env):
    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, render_mode=None):
        self.render_mode = render_mode

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(2, np.float32), {}

    def step(self, action):
        return np.zeros(2, np.float32), -1.0, False, False, {}

'''

DRIVER = '''
import contextlib
import io
import json
import sys

import evaluate_linear
import evaluate_static
import train_linear
import train_static

COMMON = ["--generations", "2", "--seed", "1", "--threads", "1"]
RUNS = {
    "strategy": (train_static, ["--environment", "CartPole-v1", "--popsize", "5", "--strategy", "random_search",
                                "--rs_step", "0.5", "--logger", "jsonl"]),
    "kind": (train_linear, ["--environment", "CartPole-v1", "--popsize", "4"]),
    "network": (train_static, ["--environment", "CartPole-v1", "--popsize", "4", "--network", "linear"]),
    "recipe": (train_static, ["--environment", "mybodies:Walker1D-v0", "--popsize", "4"]),
    "refused": (train_static, ["--environment", "CartPole-v1", "--popsize", "4", "--rs_step", "0.5"]),
}
codes = {}
for name, (script, argv) in RUNS.items():
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        codes[name] = (script.main([*argv, *COMMON, "--folder", f"runs/{name}"]), err.getvalue())
for name, script in (("kind", evaluate_linear), ("network", evaluate_static)):
    codes[f"evaluate {name}"] = (script.main(["--path_weights", f"runs/{name}", "--episodes", "2", "--json",
                                              f"{name}.json"]), "")
print(json.dumps(codes))
'''


def page_blocks() -> list[tuple[str, str]]:
    """(file, code) of each python block of the page's "Plug-in points", in order."""
    text = PAGE.read_text()
    section = text[text.index("## Plug-in points"):]
    blocks, paragraph, last, above, code, inside = [], [], "", "", [], False
    for line in section.splitlines():
        if inside:
            if line.startswith("```"):
                blocks.append((above, "\n".join(code) + "\n"))
                inside, paragraph, last, code = False, [], "", []
            else:
                code.append(line)
        elif line.startswith("```python"):
            inside, above = True, "".join(paragraph) or last
        elif line.strip():
            paragraph.append(line + " ")
        elif paragraph:  # a blank line ends a paragraph, which the block below it belongs to
            last, paragraph = "".join(paragraph), []
    placed = []
    for above, block in blocks:
        found = FIRST_PATH.search(above)
        assert above.rstrip().endswith(":") and found, f"a block of {PAGE.name} says not which file it is: {above!r}"
        placed.append((found.group(1), block))
    return placed


def add_to_registry(path: Path, lines: str) -> None:
    """A registry's new lines: an import replaces the one from the same package; a plug-in goes last in the list."""
    text = path.read_text()
    for line in lines.splitlines():
        if line.startswith("from "):
            prefix = line.split(" import ")[0] + " import "
            assert prefix in text, f"{path.name} has no line {prefix!r} for the page's {line!r}"
            text = re.sub(rf"^{re.escape(prefix)}.*$", line, text, count=1, flags=re.MULTILINE)
        elif line.strip():
            assert "\n])" in text, f"{path.name} has no registry list for the page's {line!r}"
            text = text.replace("\n])", f"\n{line}\n])", 1)
    path.write_text(text)


@pytest.fixture(scope="module")
def added(tmp_path_factory) -> Path:
    """A copy of the project with the page's five plug-ins added, and its runs made: the copy."""
    copy = tmp_path_factory.mktemp("project")
    for name in COPIED:
        shutil.copytree(ROOT / name, copy / name, ignore=shutil.ignore_patterns("__pycache__"))
    for path in ROOT.glob("*.py"):
        shutil.copy(path, copy / path.name)
    for file, code in page_blocks():
        target = copy / file
        if (ROOT / file).is_file():
            add_to_registry(target, code)
        else:
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text((WALKER if file == "mybodies.py" else "") + code)
    (copy / "driver.py").write_text(DRIVER)
    done = subprocess.run([sys.executable, "driver.py"], cwd=copy, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "SDL_VIDEODRIVER": "dummy", "PYTHONPATH": str(copy)})
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    (copy / "codes.json").write_text(done.stdout.strip().splitlines()[-1])
    return copy


def run_folder(copy: Path, name: str) -> Path:
    (run,) = (copy / "runs" / name).iterdir()
    return run


def codes(copy: Path) -> dict:
    return json.loads((copy / "codes.json").read_text())


def test_the_page_places_every_example():
    """Five modules and four registry lines (a recipe registers itself), and the two scripts of the kind."""
    files = [file for file, _ in page_blocks()]
    assert files == ["es/strategies/random_search.py", "es/strategies/__init__.py", "policies/linear.py",
                     "policies/registry.py", "train_linear.py", "evaluate_linear.py", "policies/linear_network.py",
                     "policies/networks.py", "mybodies.py", "report/loggers/jsonl.py", "report/loggers/__init__.py"]


def test_the_pages_strategy_trains_records_only_its_settings_and_refuses_its_flag_without_it(added):
    assert codes(added)["strategy"][0] == 0
    config = json.loads((run_folder(added, "strategy") / "config.json").read_text())
    assert set(config["es"]) == {item.name for item in options(SearchSettings)} | {"rs_step"}
    assert config["es"]["strategy"] == "random_search" and config["es"]["rs_step"] == 0.5
    assert config["es"]["popsize"] == 5  # an odd population: its members are no pairs
    code, err = codes(added)["refused"]
    assert code == 2 and err.strip().splitlines() == [
        "train_static.py: error: --rs_step has an effect only with --strategy random_search; add --strategy "
        "random_search or leave --rs_step out"]
    assert not (added / "runs" / "refused").exists()


def test_the_pages_logger_has_every_row(added):
    rows = [json.loads(line) for line in (run_folder(added, "strategy") / "metrics.jsonl").read_text().splitlines()]
    assert [row["generation"] for row in rows] == [1, 2] and all("fitness_mean" in row for row in rows)


def test_the_pages_policy_kind_trains_and_evaluates_through_its_own_scripts(added):
    assert codes(added)["kind"][0] == 0 and codes(added)["evaluate kind"][0] == 0
    run = run_folder(added, "kind")
    config = json.loads((run / "config.json").read_text())
    assert config["policy"]["kind"] == "linear" and "network" not in config["policy"]
    assert config["num_params"] == 2 * 4  # CartPole: 4 observations, 2 actions
    assert (run / "last.dat").is_file() and len(json.loads((added / "kind.json").read_text())["environments"]) == 1


def test_the_pages_network_trains_with_train_static(added):
    assert codes(added)["network"][0] == 0 and codes(added)["evaluate network"][0] == 0
    config = json.loads((run_folder(added, "network") / "config.json").read_text())
    assert config["policy"]["kind"] == "static" and config["policy"]["network"] == "linear"
    assert config["num_params"] == 2 * 4


def test_the_pages_recipe_stops_its_episodes(added):
    assert codes(added)["recipe"][0] == 0
    run = run_folder(added, "recipe")
    config = json.loads((run / "config.json").read_text())
    assert config["env"]["recipe_modules"] == ["mybodies"]
    assert "NegativeRewardStop" in config["wrappers"]["mybodies:Walker1D-v0"]
    assert {int(row["env_steps"]) for row in read_metrics(run / "metrics.csv")} == {5 * 31}  # 4 members + centre


# --- the registry itself -------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Base:
    choice: str = setting("a", choices=("a", "b"))

    def __post_init__(self) -> None:
        check(self)


@dataclasses.dataclass(frozen=True)
class OwnSettings:
    size: int = setting(3, low=1, help="its size")


def test_a_registry_refuses_a_second_plugin_of_a_name_and_names_the_valid_ones():
    registry = Registry("choice", [Plugin("a"), Plugin("b")])
    with pytest.raises(ValueError, match="two plug-ins are named 'a' for --choice"):
        registry.add(Plugin("a"))
    registry.add(Plugin("a", about="again"), replace=True)
    assert list(registry) == ["b", "a"] and registry["a"].about == "again"
    with pytest.raises(KeyError, match="unknown choice 'c'; valid: b, a"):
        registry["c"]


def test_joined_settings_are_owned_by_their_plugin():
    """A plug-in's field comes after the base's, owned by it: a value other than its default without it chosen is
    refused; two plug-ins declaring one field, or a field not made with setting(), are refused as the class is made."""
    registry = Registry("choice", [Plugin("a"), Plugin("b", settings=OwnSettings)])
    Joined = joined(Base, registry, name="Joined", module=__name__)
    assert [(item.name, item.spec.owner) for item in options(Joined)] == [("choice", None), ("size", ("choice", "b"))]
    assert Joined(choice="b", size=5).size == 5 and Joined().size == 3
    with pytest.raises(ValueError, match="^--size has an effect only with --choice b; leave it out$"):
        Joined(size=5)
    with pytest.raises(TypeError, match="declared twice"):
        joined(Base, Registry("choice", [Plugin("a", settings=OwnSettings), Plugin("b", settings=OwnSettings)]),
               name="Twice", module=__name__)
    plain = dataclasses.make_dataclass("Plain", [("size", int, dataclasses.field(default=3))], frozen=True)
    with pytest.raises(TypeError, match="not declared with settings.setting"):
        joined(Base, Registry("choice", [Plugin("a", settings=plain)]), name="Plain", module=__name__)


def test_every_plugin_setting_names_its_owner_in_its_help_and_no_setting_is_declared_twice():
    names = [item.name for item in declared()]
    assert len(names) == len(set(names))
    owned = [item for item in options(ESSettings) if item.spec.owner is not None]
    assert owned and all(item.spec.owner[0] == "strategy" for item in owned)
