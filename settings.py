"""One declaration per option: a settings dataclass field made with ``setting()`` (in the style of tyro and
Hydra's structured configs). Everything else about the option is derived from that field:

- the flags of the four scripts (``cli.flags.add_settings``), their help with the default shown once,
  and the docs' flag tables (``cli.flags.flag_table``);
- the TOML keys of an experiment file and ``config.json`` in both directions (``cli.config``);
- the checks (``check``, called by each dataclass's ``__post_init__``), one line naming the flag;
- the "has an effect only with" rules (``requires``), the settings a ``--resume`` may change
  (``resumable``), and the settings the evaluate scripts take from a run (``evaluation``);
- for a plug-in's setting (``plugins``: a strategy's, a logger's, a policy kind's), its owner: it has an
  effect only with its plug-in chosen, and a run records it only then (``chosen``).

This module imports nothing of the project, so that every package (``es``, ``policies``, ``envs``) can
declare its settings with it. To add an option, add one field, e.g. to OpenAI-ES's settings
(``es.strategies.openai.OpenAISettings``, which ``es.settings.ESSettings`` joins):

    momentum: float = setting(0.9, help="with --optimizer momentum", low=0, high=1, high_open=True,
                              requires=("optimizer", "momentum"))

and it is a flag of both training scripts, a TOML key of ``[es]``, a key of config.json (of the runs of
``--strategy openai``), checked, and refused without ``--optimizer momentum``. The metadata (all optional but
the default):

    help             the flag's help; the default is appended by cli.flags, once
    flag             the flag's name without dashes (default: the field's name); None: no flag, a key of
                     experiment files and config.json only (e.g. the original's hard-coded constants)
    aliases          other programs' flags giving a value: {"useAdam": "adam"} (pytorch-es's --useAdam)
    choices          the valid values, or a function returning them (a registry defined further up)
    low, high        a number's range, closed unless low_open / high_open; whole numbers by the type
    nonempty         a string that must not be empty
    rule             (predicate, what it expects) for a rule no range says (--threads: -1 or >= 1)
    parse            the argparse type of the flag (default: the field's type)
    metavar, group   how --help shows it
    shown_default    what --help says the default is, where the field's is a placeholder (a random seed)
    scripts          "train", "evaluate": whose flag it is (default: training only)
    resumable        True: --resume may change it (it changes no result: threads, more generations)
    evaluation       True: the evaluate scripts take it from the run's config.json (what shapes the policy)
    requires         (setting, value): it has an effect only when that setting has that value; value ANY:
                     when that setting is on (true, or not None); several pairs: when all hold
    derived          True: filled in by the program (the resolved environment ids), never given
    owner            (choice, plug-in): the plug-in whose setting it is, e.g. ("strategy", "pgpe"); set by
                     ``plugins.joined`` from the plug-in that declares it, never by hand
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from collections.abc import Callable
from typing import Any

SEED_RANGE = (0, 2**31 - 1)  # every seed the project takes: numpy's and Gymnasium's int32 seeds
# an evaluated episode's seed: the training's seeds, and those of the centre's evaluation (``es.loop.EVAL_SEEDS``,
# from 2**31 on, which no training episode uses); Gymnasium seeds an episode from any of them
EPISODE_SEED_RANGE = (0, 2**32 - 1)
ANY = object()  # ``requires=("eval_every", ANY)``: any value but off (False, None)
# the largest float32: the parameters are float32, and so is the fitness the original's Fitness_values file
# records; a scale above it (--sigma, --fitness_l2) overflows them for any value of magnitude 1 or more
FLOAT32_MAX = 3.4028234663852886e38
MODERN = "beyond the original algorithm (defaults: the original)"  # --help's group of the options the original lacks


def optional_float(text: str) -> float | None:
    """A flag's number, or ``none`` for no value."""
    return None if text.strip().lower() == "none" else float(text)


@dataclasses.dataclass(frozen=True)
class Spec:
    help: str = ""
    flag: str | None = ""  # "": the field's name
    aliases: dict = dataclasses.field(default_factory=dict)
    choices: Any = None
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    nonempty: bool = False
    rule: tuple | None = None
    parse: Callable | None = None
    metavar: str | None = None
    group: str | None = None
    shown_default: str | None = None
    scripts: tuple[str, ...] = ("train",)
    resumable: bool = False
    evaluation: bool = False
    requires: tuple | None = None
    derived: bool = False
    owner: tuple[str, str] | None = None


def setting(default, **metadata) -> Any:
    """A dataclass field holding ``default`` and its ``Spec`` (the keys above)."""
    return dataclasses.field(default=default, metadata={"setting": Spec(**metadata)})


@dataclasses.dataclass(frozen=True)
class Option:
    """One declared setting, as the code that derives things from it sees it."""

    name: str
    default: Any
    hint: Any
    spec: Spec

    @property
    def flag(self) -> str | None:
        return self.name if self.spec.flag == "" else self.spec.flag

    @property
    def label(self) -> str:
        """How messages name it: its flag, or for a setting without one its key."""
        return f"--{self.flag}" if self.flag else self.name

    @property
    def choices(self) -> tuple | None:
        choices = self.spec.choices
        return None if choices is None else tuple(choices() if callable(choices) else choices)

    @property
    def many(self) -> bool:
        """A tuple of values (``--logger wandb mlflow``), each one of the choices if there are any."""
        return typing.get_origin(self.base_type()) is tuple

    def base_type(self):
        """The field's type without ``| None``."""
        options = [item for item in _union(self.hint) if item is not type(None)]
        return options[0] if len(options) == 1 else self.hint


def options(settings) -> tuple[Option, ...]:
    """The declared settings of a settings dataclass (or instance), in declaration order."""
    return _options(settings if isinstance(settings, type) else type(settings))


@functools.cache
def _options(cls: type) -> tuple[Option, ...]:
    hints = typing.get_type_hints(cls)
    return tuple(Option(item.name, item.default, hints[item.name], item.metadata.get("setting", Spec()))
                 for item in dataclasses.fields(cls))


# --- checks -------------------------------------------------------------------------------------------


def _union(hint) -> tuple:
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return typing.get_args(hint)
    return (hint,)


TYPE_NAMES = {bool: "true or false", int: "a whole number", float: "a number", str: "a string",
              type(None): "none"}


def _of_type(value, hint) -> bool:
    if typing.get_origin(hint) is tuple:
        return isinstance(value, (list, tuple))
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, hint)


def file_value(item: Option, value):
    """A value of an experiment file: TOML has no null, so where the flag takes ``none`` for no value
    (``optional_float``), the file's string "none" is no value too."""
    if isinstance(value, str) and item.spec.parse is not None and type(None) in _union(item.hint):
        try:
            if item.spec.parse(value) is None:
                return None
        except (TypeError, ValueError):
            pass
    return value


def type_problem(item: Option, value) -> str | None:
    """What is wrong with the type of ``value`` (a file can hold anything: ``reservoir = "false"``)."""
    if any(_of_type(value, hint) for hint in _union(item.hint)):
        return None
    expected = " or ".join(TYPE_NAMES.get(hint, "a list") for hint in _union(item.hint))
    return f"{item.label} must be {expected}, got {value!r}"


def expected(item: Option) -> str:
    """What a valid value is, in words: 'a whole number >= 1', 'in [0, 1)', 'one of sgd, adam'."""
    spec = item.spec
    if spec.rule is not None:
        return spec.rule[1]
    if item.choices is not None:
        return f"{'one or more' if item.many else 'one'} of {', '.join(map(str, item.choices))}"
    if spec.nonempty:
        return "a non-empty string"
    whole = item.base_type() is int
    low, high = spec.low, spec.high
    if whole and low is not None and high is not None:
        return f"a whole number from {low} to {high}"
    if low is not None and high is not None:
        return f"in {'(' if spec.low_open else '['}{low:g}, {high:g}{')' if spec.high_open else ']'}"
    if low is not None:
        return f"{'a whole number' if whole else 'a number'} {'>' if spec.low_open else '>='} {low:g}"
    return TYPE_NAMES.get(item.base_type(), "valid")


def value_problem(item: Option, value) -> str | None:
    """What is wrong with ``value`` for this setting, in one line naming its flag; None if nothing."""
    problem = type_problem(item, value)
    if problem is not None or value is None:
        return problem
    spec = item.spec
    if spec.rule is not None:
        valid = spec.rule[0](value)
    elif item.choices is not None:
        valid = all(one in item.choices for one in value) if item.many else value in item.choices
    elif spec.nonempty:
        valid = bool(value.strip())
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        valid = math.isfinite(value) and _in_range(spec, value)
    else:
        valid = True
    shown = repr(value) if isinstance(value, str) else " ".join(map(str, value)) if item.many else value
    return None if valid else f"{item.label} must be {expected(item)}, got {shown}"


def _in_range(spec: Spec, value) -> bool:
    if spec.low is not None and (value <= spec.low if spec.low_open else value < spec.low):
        return False
    return spec.high is None or (value < spec.high if spec.high_open else value <= spec.high)


def check(settings) -> None:
    """Refuse, in a ValueError naming the flag, the first field of ``settings`` whose value is not valid
    (whether it came from a flag, an experiment file or a config.json), or that sets a plug-in not chosen
    (``stray``). Lists become tuples."""
    declared = options(settings)
    for item in declared:
        value = getattr(settings, item.name)
        if isinstance(value, list) and typing.get_origin(item.base_type()) is tuple:
            object.__setattr__(settings, item.name, tuple(value))  # frozen: before anyone has seen it
            value = tuple(value)
        problem = value_problem(item, value)
        if problem is not None:
            raise ValueError(problem)
    values = {item.name: getattr(settings, item.name) for item in declared}
    for item in declared:
        if stray(item, values[item.name], values, declared):
            raise ValueError(f"{item.label} has an effect only with {owner_words(item, declared)}; leave it out")


# --- plug-ins' settings -----------------------------------------------------------------------------------


def _choice(item: Option, declared) -> Option:
    """The setting that chooses the plug-in ``item`` belongs to."""
    return next(entry for entry in declared if entry.name == item.spec.owner[0])


def _names(value, plugin: str) -> bool:
    """Whether a choice's value names ``plugin`` (one of them, for a choice of several: --logger)."""
    return plugin in value if isinstance(value, (tuple, list)) else value == plugin


def left_out_by(item: Option, values: dict, declared) -> Option | None:
    """The choice that leaves ``item`` out in ``values``: the setting that chooses its plug-in, where it names
    another, or the one that chooses the plug-in that choice belongs to, and so on up (a network's setting: the
    network chosen, then the policy kind, which must be the static one that takes networks). None where every
    one names its plug-in, or for a setting of no plug-in; a choice that ``values`` lack counts as made (a
    script's flags: only its kind is known)."""
    while item.spec.owner is not None:
        choice, plugin = item.spec.owner
        option = _choice(item, declared)
        if choice in values and not _names(values[choice], plugin):
            return option
        item = option
    return None


def chosen(item: Option, values: dict, declared) -> bool:
    """Whether ``item`` is a setting of no plug-in, or of plug-ins that ``values`` choose (``left_out_by``)."""
    return left_out_by(item, values, declared) is None


def stray(item: Option, value, values: dict, declared) -> bool:
    """A value of a plug-in not chosen that no run could have: not its default, and not one that a resume may
    change or the program fills in (a tracker's run id, kept by a resume that logs elsewhere)."""
    return (item.spec.owner is not None and not chosen(item, values, declared) and value != item.default
            and not (item.spec.resumable or item.spec.derived))


def owner_words(item: Option, declared) -> str:
    """Its plug-in in words: '--strategy pgpe'; for a choice the script makes (the policy kind), 'hebbian runs'."""
    choice, plugin = item.spec.owner
    label = _choice(item, declared).flag
    return f"--{label} {plugin}" if label else f"{plugin} runs"


# --- rules between settings ---------------------------------------------------------------------------


def requirements(item: Option, declared) -> list[tuple[str, Callable[[dict], bool]]]:
    """What ``item`` needs, one condition at a time: in words ("--optimizer adam"), and whether merged values
    meet it. Its plug-in comes first, where a flag chooses it ("--strategy pgpe"; the policy kind is the
    script's), then what it ``requires``."""
    pairs = [] if item.spec.requires is None else (
        list(item.spec.requires) if isinstance(item.spec.requires[0], tuple) else [item.spec.requires])
    if item.spec.owner is not None and _choice(item, declared).flag:
        pairs.insert(0, item.spec.owner)
    found = []
    for name, wanted in dict.fromkeys(pairs):
        other = next(entry for entry in declared if entry.name == name)
        if wanted is ANY or wanted is True:
            found.append((other.label, lambda values, name=name: values.get(name) not in (None, False)))
        elif other.many:  # one of the values given: --wandb_project with --logger wandb (among others)
            found.append((f"{other.label} {wanted}",
                          lambda values, name=name, wanted=wanted: wanted in (values.get(name) or ())))
        else:
            found.append((f"{other.label} {wanted}",
                          lambda values, name=name, wanted=wanted: values.get(name) == wanted))
    return found


def requirement(item: Option, declared) -> tuple[str, Callable[[dict], bool]] | None:
    """What ``item`` needs, in words ("--strategy openai --optimizer adam"), and whether merged values have it."""
    found = requirements(item, declared)
    if not found:
        return None
    return " ".join(words for words, _ in found), lambda values: all(test(values) for _, test in found)


def unmet_requirement(declared, values: dict, given) -> str | None:
    """The first given setting that would do nothing with these values, as one line: what it needs, and what of
    that it lacks."""
    for item in (item for item in declared if item.name in given):
        found = requirements(item, declared)
        unmet = [words for words, test in found if not test(values)]
        if unmet:
            needed = " ".join(words for words, _ in found)
            return f"{item.label} has an effect only with {needed}; add {' '.join(unmet)} or leave {item.label} out"
    return None


def contradictions(recorded: dict, given: dict, declared) -> list[str]:
    """``--name value (the run has recorded)`` for each given value that differs from the recorded one."""
    labels = {item.name: item.label for item in declared}
    return [f"{labels.get(name, '--' + name)} {value} (the run has {recorded[name]})"
            for name, value in given.items() if name in recorded and value != recorded[name]]
