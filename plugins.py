"""Plug-ins: the one mechanism behind every point where the project takes additions -- strategies
(``es.strategies``), policy kinds and static networks (``policies.registry``), experiment trackers
(``report.loggers``) and environment recipes (``envs.recipes``).

A plug-in is a frozen dataclass subclassing ``Plugin``, declared in a module of its own: its name, a line
saying what it is, its own settings, and the rules its point asks of it (a strategy's population rule, a
logger's packages, a policy kind's scripts), those whose default could do harm declared without one. A
``Registry`` lists a point's plug-ins, one line each, in order; ``choice`` is the setting that names the
plug-in of a run (``--strategy``, ``--logger``, the policy kind, ``--network``).

A plug-in's settings are a frozen dataclass holding only its own fields, each made with
``settings.setting()``. ``joined`` makes one section of settings from a base dataclass, which declares the
choice, and every plug-in's settings after it, each field marked with its owner (``settings.Spec.owner``:
the choice and the plug-in). From that mark alone, without a word from the plug-in:

- the setting is a flag of the scripts, a TOML key, a config.json key and a row of the flag tables
  (``cli.flags``, ``cli.config``), its help saying what it needs ("with --strategy pgpe");
- it has an effect only with its plug-in chosen: given without it, it is refused in one line
  (``settings.unmet_requirement``), and a value other than its default for a plug-in not chosen is refused
  (``settings.check``);
- config.json records it only for a run that chooses its plug-in (``cli.config``); a config.json of an
  earlier version, which recorded every plug-in's settings, is read with the others left out.

This module imports nothing of the project but ``settings``, so that every package can declare its plug-ins.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Iterable, Iterator, Mapping
from typing import Generic, TypeVar

from settings import Spec


@dataclasses.dataclass(frozen=True)
class Plugin:
    """What every plug-in declares: the name its choice gives it (``--strategy pgpe``), what it is in a few
    words (the choice's help lists them), and its own settings."""

    name: str
    about: str = dataclasses.field(default="", kw_only=True)
    settings: type | None = dataclasses.field(default=None, kw_only=True)  # a frozen dataclass; None: it has none


P = TypeVar("P", bound=Plugin)


class Registry(Mapping[str, P], Generic[P]):
    """The plug-ins of one point, by name, in the order they were added."""

    def __init__(self, choice: str | None, plugins: Iterable[P] = ()):
        self.choice = choice  # the setting that names a run's plug-in; None: chosen otherwise (a recipe matches)
        self._plugins: dict[str, P] = {}
        for plugin in plugins:
            self.add(plugin)

    def add(self, plugin: P, replace: bool = False) -> P:
        """Add ``plugin`` last; a name already taken is refused, or with ``replace`` its plug-in is removed first."""
        if plugin.name in self._plugins and not replace:
            raise ValueError(f"two plug-ins are named {plugin.name!r}{self._of()}; give this one another name")
        self._plugins.pop(plugin.name, None)
        self._plugins[plugin.name] = plugin
        return plugin

    def __getitem__(self, name: str) -> P:
        try:
            return self._plugins[name]
        except (KeyError, TypeError):
            raise KeyError(f"unknown {self.choice or 'plug-in'} {name!r}; valid: {', '.join(self._plugins)}") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._plugins)

    def __len__(self) -> int:
        return len(self._plugins)

    def values(self):  # the dict's own views: in order, and reversible (the last registered recipe first)
        return self._plugins.values()

    def items(self):
        return self._plugins.items()

    def __repr__(self) -> str:
        return f"Registry({self.choice!r}, {list(self._plugins)})"

    def described(self, separator: str = ", ") -> str:
        """Each plug-in's name with what it is: 'openai (Salimans et al. 2017), pgpe (...)'."""
        return separator.join(f"{name} ({plugin.about})" if plugin.about else name
                              for name, plugin in self._plugins.items())

    def _of(self) -> str:
        return f" for --{self.choice}" if self.choice else ""


# what dataclasses makes for a class: not copied from a section's base to the class ``joined`` makes
_MADE = {"__dict__", "__weakref__", "__dataclass_fields__", "__dataclass_params__", "__init__", "__repr__", "__eq__",
         "__hash__", "__setattr__", "__delattr__", "__match_args__", "__annotations__", "__doc__", "__module__",
         "__qualname__"}


def joined(base: type, *registries: Registry, name: str, module: str) -> type:
    """A frozen dataclass ``name`` (of ``module``, where it is bound to that name) with ``base``'s fields and
    methods, and after each registry's choice field the settings of every plug-in of that registry, in its
    order, each marked with its owner. A field that two of them declare, a field not made with
    ``settings.setting()`` and a registry whose choice no field before it declares are refused."""
    hints = typing.get_type_hints(base)
    fields = [(field.name, hints[field.name], _field(field, field.metadata.get("setting")))
              for field in dataclasses.fields(base)]
    taken = {field for field, *_ in fields}
    for registry in registries:
        at = next((index for index, (field, *_) in enumerate(fields) if field == registry.choice), None)
        if at is None:
            raise TypeError(f"{name}: no setting {registry.choice!r} chooses among {list(registry)}")
        owned = [entry for plugin in registry.values() for entry in _owned(registry, plugin)]
        for field, _, made in owned:
            if field in taken:
                raise TypeError(f"{registry.choice} {made.metadata['setting'].owner[1]}'s setting {field!r} is "
                                f"declared twice in {name}")
            taken.add(field)
        fields[at + 1:at + 1] = owned
    methods = {key: value for key, value in vars(base).items() if key not in _MADE and key not in hints}
    made = dataclasses.make_dataclass(name, fields, namespace=methods, frozen=True)
    made.__module__, made.__doc__ = module, base.__doc__  # pickled and shown as ``module.name``
    return made


def _field(field: dataclasses.Field, spec: Spec | None) -> dataclasses.Field:
    """A copy of ``field`` with ``spec`` as its setting."""
    metadata = {**field.metadata, **({"setting": spec} if spec is not None else {})}
    if field.default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=field.default_factory, metadata=metadata)
    return dataclasses.field(default=field.default, metadata=metadata)


def _owned(registry: Registry, plugin: Plugin) -> list[tuple[str, object, dataclasses.Field]]:
    """The fields of ``plugin``'s settings, each marked with its owner."""
    if plugin.settings is None:
        return []
    hints = typing.get_type_hints(plugin.settings)
    found = []
    for field in dataclasses.fields(plugin.settings):
        spec = field.metadata.get("setting")
        if not isinstance(spec, Spec):
            raise TypeError(f"{registry.choice} {plugin.name}'s setting {field.name!r} is not declared with "
                            "settings.setting()")
        found.append((field.name, hints[field.name],
                      _field(field, dataclasses.replace(spec, owner=(registry.choice, plugin.name)))))
    return found
