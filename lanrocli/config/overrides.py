"""Settings given on the command line as ``KEY=VALUE`` (``lanro train``, ``check`` and ``sweep``'s ``--set``,
``sweep``'s ``--grid``), read the same way by every command.

Keys are the curriculum's own key paths, as its error messages name them (``agent.critics``,
``stages[0].budget.steps``, ``eval.episodes``), and values are read as YAML (``2``, ``0.5``, ``true``,
``[ambiguity]``). A changed curriculum is validated as a file is, and each problem is located at the option
that caused it (``--set agent.critcs=2: agent.critcs: unknown key 'critcs'; did you mean 'critics'?``).
"""

from __future__ import annotations

import json
import re
from typing import Any

import yaml

from lanrocli.config.yamlfile import CurriculumError, KeyPath, Marks, Model, Problem, format_key, given_by, validate

_SEGMENT = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)")

Setting = tuple[str, str, Any]
"""A setting as given: the option that gave it (``--set``), its key path as written, its value read."""


class SettingError(ValueError):
    """A ``KEY=VALUE`` option that cannot be read, or whose key has no place in the curriculum."""


def parse_key(text: str) -> KeyPath:
    """``stages[0].budget.steps`` as ``("stages", 0, "budget", "steps")``."""
    path: list[str | int] = []
    for part in text.split("."):
        match = _SEGMENT.fullmatch(part)
        if match is None:
            raise SettingError(f"{text!r} is not a key path such as agent.critics or stages[0].budget.steps")
        path.append(match.group(1))
        path.extend(int(index) for index in re.findall(r"\d+", match.group(2)))
    return tuple(path)


def show(value: Any) -> str:
    """A value as it would be written on the command line."""
    return value if isinstance(value, str) else json.dumps(value)


def read_value(option: str, text: str) -> Any:
    """``text`` read as YAML; ``option`` (the option and its whole argument) names it in the error."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise SettingError(f"{option}: {text!r} is not a YAML value: {getattr(error, 'problem', error)}") from None


def split_setting(option: str, text: str, seed_option: str | None = None) -> tuple[str, str]:
    """``KEY=VALUE`` as its key and the text of its value. Where the command gives seeds an option of its
    own, ``seed_option``, that treats them apart from the curriculum (a sweep's seeds are its trials), the
    seed is refused here."""
    key, equals, value = text.partition("=")
    if not equals or not key:
        raise SettingError(f"{option} {text}: expected KEY=VALUE, e.g. {option} agent.critics=2")
    if seed_option is not None and parse_key(key)[0] == "seed":
        raise SettingError(f"{option} {text}: give seeds with {seed_option}")
    return key, value


def read_settings(option: str, texts: list[str], seed_option: str | None = None) -> dict[str, Any]:
    """Every ``KEY=VALUE`` of ``texts`` by its key, values read; a key given twice is refused."""
    settings: dict[str, Any] = {}
    for text in texts:
        key, value = split_setting(option, text, seed_option)
        if key in settings:
            raise SettingError(f"{option} {key} is given twice")
        settings[key] = read_value(f"{option} {text}", value)
    return settings


def put(data: dict[str, Any], path: KeyPath, value: Any) -> None:
    """Set ``path`` in ``data`` to ``value``; a missing key is added (the curriculum's check names it)."""
    node: Any = data
    for depth, key in enumerate(path):
        where = format_key(path[: depth + 1])
        last = depth == len(path) - 1
        if isinstance(node, dict) and isinstance(key, str):
            if last:
                node[key] = value
            else:
                node = node.setdefault(key, {})
        elif isinstance(node, list) and isinstance(key, int):
            if key >= len(node):
                raise SettingError(
                    f"{where}: {format_key(path[:depth])} has {len(node)} items, [0] to [{len(node) - 1}]"
                )
            if last:
                node[key] = value
            else:
                node = node[key]
        else:
            kind = "a list" if isinstance(node, list) else "a mapping" if isinstance(node, dict) else repr(node)
            raise SettingError(
                f"{where}: {format_key(path[:depth]) or 'the curriculum'} is {kind}, which has no {key!r}"
            )


def flatten(data: Any, prefix: KeyPath = ()) -> dict[str, Any]:
    """Every value of nested mappings and lists by its key path, as ``--set`` names them."""
    if isinstance(data, dict):
        items: Any = data.items()
    elif isinstance(data, list):
        items = enumerate(data)
    else:
        return {format_key(prefix): data}
    flat: dict[str, Any] = {}
    for key, value in items:
        flat.update(flatten(value, (*prefix, key)))
    return flat


def apply_settings(model: type[Model], data: dict[str, Any], settings: list[Setting], source: str) -> Model:
    """``data`` (a curriculum's, which is changed) with every setting put at its key path, validated as
    ``model``. Every problem is a ``CurriculumError``, all of them at once: a key with no place in the data at
    the setting that named it, and what validation finds at the setting that gave the value, or at the line
    of ``source`` (the curriculum the data came from) that still holds it."""
    problems: list[Problem] = []
    marks: Marks = {}
    for option, key, value in settings:
        label = f"{option} {key}={show(value)}"
        try:
            put(data, parse_key(key), value)
        except SettingError as error:
            problems.append(Problem(label, None, "", str(error)))
            continue
        marks.update(given_by(label, [parse_key(key)]))
    context = " ".join([source, *(["with"] if settings else []), *(f"{o} {k}={show(v)}" for o, k, v in settings)])
    try:
        validated = validate(model, data, marks, context)
    except CurriculumError as error:
        problems.extend(error.problems)
    else:
        if not problems:
            return validated
    raise CurriculumError(problems)
