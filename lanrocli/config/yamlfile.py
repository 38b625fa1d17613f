"""Curriculum files as data: YAML with ``extends``, every key's line remembered, problems located.

``extends: other.yaml`` (top level only; the path is relative to the directory of the file that names it)
builds a file on top of another, in chains of any length. The merge rule: mappings merge key by key,
recursively; every other value, lists included, replaces the parent's value wholesale. So a child that
sets ``agent: {batch_size: 128}`` keeps the parent's other agent settings, while a child that sets
``stages`` replaces all of the parent's stages: merging stage lists item by item would make the result
depend on positions the child cannot see.

Validation is a pydantic model's; what it finds wrong becomes a list of :class:`Problem`, each with its
file, line and key path, so one edit fixes them all.

A file is bounded before it is expanded (``MAX_BYTES``, then ``MAX_VALUES`` and ``MAX_DEPTH`` while
composing), so that no input, an alias bomb included, costs more than a moment to refuse; and a key written
twice in one mapping is a problem rather than PyYAML's silent choice of the last.
"""

from __future__ import annotations

import difflib
import re
import reprlib
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

import yaml
from pydantic import BaseModel, ValidationError
from pydantic_core import ErrorDetails

KeyPath = tuple[str | int, ...]
Model = TypeVar("Model", bound=BaseModel)


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a curriculum, located as precisely as the file allows."""

    file: Path | str
    line: int | None
    path: str
    message: str

    def __str__(self) -> str:
        where = str(self.file) if self.line is None else f"{self.file}:{self.line}"
        return ": ".join(part for part in (where, self.path, self.message) if part)


class KeyProblem(ValueError):
    """A check of a whole section that finds the problem at one key inside it: raised from a validator of
    the section, it is reported at that key's line."""

    def __init__(self, key: KeyPath, message: str) -> None:
        super().__init__(message)
        self.key = key


class CurriculumError(ValueError):
    """A curriculum that cannot be used; ``problems`` lists everything found, not just the first."""

    def __init__(self, problems: list[Problem]) -> None:
        super().__init__("\n".join(str(problem) for problem in problems))
        self.problems = problems


EXTENDS = "extends"


class _Mark(NamedTuple):
    file: Path | str
    line: int | None


Marks = dict[KeyPath, _Mark]
"""The file and line of every key and list item, by key path."""


def read(path: Path) -> tuple[dict[str, Any], Marks]:
    """The data of the YAML file at ``path`` merged onto the files it extends, and where each key is."""
    return _resolve(path, (path.resolve(),), None)


MAX_BYTES = 1_000_000
"""The largest curriculum file read; the shipped ones are a few kilobytes."""
MAX_VALUES = 10_000
"""The most values (keys, scalars, lists and mappings) a document may hold, an alias counting as all the
values it repeats; the shipped curricula hold about a hundred. Counted while composing, the bound stops an
alias bomb (nine anchors, each a list of nine aliases of the one before: a few hundred bytes that expand to
9**9 values) before it expands, and a dense file before PyYAML's pure-Python reader, at tens of thousands
of values a second, has spent more than a moment on it."""
MAX_DEPTH = 50
"""The deepest nesting of lists and mappings; a curriculum nests six levels. PyYAML composes recursively,
so a deeper document could reach Python's recursion limit."""

_BOOL_TAG = "tag:yaml.org,2002:bool"


class _Refused(yaml.MarkedYAMLError):
    """A valid YAML document that is no curriculum, refused while composing, before it is expanded."""


class _Loader(yaml.SafeLoader):
    """Safe loading with YAML 1.2 booleans (only true/false), within ``MAX_VALUES`` and ``MAX_DEPTH``.
    PyYAML follows YAML 1.1, where the key ``on`` of ``promote`` would load as the boolean True."""

    yaml_implicit_resolvers = {
        first: [(tag, regexp) for tag, regexp in resolvers if tag != _BOOL_TAG]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
    }

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self._values = 0
        self._depth = 0
        self._sizes: dict[yaml.Node, int] = {}  # values in each complete node, aliases expanded

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node:
        if self.check_event(yaml.AliasEvent):
            self._count_alias(self.peek_event())
            return super().compose_node(parent, index)
        self._depth += 1
        if self._depth > MAX_DEPTH:
            problem = f"lists and mappings nested more than {MAX_DEPTH} deep, where a curriculum nests six"
            raise _Refused(problem=problem, problem_mark=self.peek_event().start_mark)
        before = self._values
        node = super().compose_node(parent, index)
        self._depth -= 1
        self._count(1, node.start_mark)
        self._sizes[node] = self._values - before
        return node

    def _count_alias(self, event: yaml.AliasEvent) -> None:
        target = self.anchors.get(event.anchor)
        if target is None:
            return  # an unknown anchor: PyYAML's own error follows
        if target not in self._sizes:  # still being composed: the alias is inside the value it names
            problem = f"the alias *{event.anchor} is inside the value it names, which would make it endless"
            raise _Refused(problem=problem, problem_mark=event.start_mark)
        self._count(self._sizes[target], event.start_mark)

    def _count(self, values: int, mark: yaml.Mark) -> None:
        self._values += values
        if self._values > MAX_VALUES:
            problem = (
                f"more than {MAX_VALUES:,} values by here, an alias (*name) counting as all the values it "
                "repeats, where a curriculum holds a few hundred; is this a curriculum?"
            )
            raise _Refused(problem=problem, problem_mark=mark)

    def construct_object(self, node: yaml.Node, deep: bool = False) -> Any:
        """A scalar that looks like a date or a number but is none (``2024-13-01``, ``0x_``) makes PyYAML
        raise a bare ValueError; here it becomes an error at the scalar's line."""
        try:
            return super().construct_object(node, deep)
        except ValueError as error:
            problem = f"cannot read {reprlib.repr(node.value)} ({error}); quote it if it is text"
            raise yaml.constructor.ConstructorError(problem=problem, problem_mark=node.start_mark) from None


_Loader.add_implicit_resolver(_BOOL_TAG, re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF"))


def _resolve(path: Path, chain: tuple[Path, ...], named_at: _Mark | None) -> tuple[dict[str, Any], Marks]:
    """``path`` merged onto the files it extends. ``chain`` holds the files being loaded, to find cycles;
    ``named_at`` is the ``extends`` that named ``path``, where a file that cannot be read is reported."""
    try:
        with path.open("rb") as file:
            raw = file.read(MAX_BYTES + 1)
    except OSError as error:
        reason = "no such file" if isinstance(error, FileNotFoundError) else f"cannot read it: {error}"
        if named_at is None:
            raise CurriculumError([Problem(path, None, "", reason)]) from None
        raise CurriculumError([Problem(named_at.file, named_at.line, EXTENDS, f"{path}: {reason}")]) from None
    data, marks = parse(_text(raw, path), path)
    if EXTENDS not in data:
        return data, marks
    parent_name = data.pop(EXTENDS)
    here = marks.pop((EXTENDS,), _Mark(path, None))
    if not isinstance(parent_name, str) or not parent_name:
        raise CurriculumError([Problem(here.file, here.line, EXTENDS, "must name the YAML file to build on")])
    parent = path.parent / parent_name
    if parent.resolve() in chain:
        cycle = " -> ".join(str(file) for file in (*chain, parent.resolve()))
        message = f"extending {parent} makes a cycle: {cycle}"
        raise CurriculumError([Problem(here.file, here.line, EXTENDS, message)])
    parent_data, parent_marks = _resolve(parent, (*chain, parent.resolve()), here)
    kept = {key: mark for key, mark in parent_marks.items() if not _replaced(key, parent_data, data)}
    return _merge(parent_data, data), kept | marks


def _text(raw: bytes, file: Path) -> str:
    """The text of a curriculum file of ``raw`` bytes, read up to one byte past ``MAX_BYTES``."""
    if len(raw) > MAX_BYTES:
        message = f"larger than {MAX_BYTES:,} bytes, far more than a curriculum needs; is it the right file?"
        raise CurriculumError([Problem(file, None, "", message)])
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as error:
        line = raw.count(b"\n", 0, error.start) + 1
        message = f"not UTF-8 text ({error.reason} at byte {error.start}); save the file as UTF-8"
        raise CurriculumError([Problem(file, line, "", message)]) from None


def parse(text: str, file: Path | str) -> tuple[dict[str, Any], Marks]:
    """The data of one YAML document, and the line of every key and list item in it."""
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        data = None if node is None else loader.construct_document(node)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        reason = getattr(error, "problem", None) or str(error)
        line = None if mark is None else mark.line + 1
        message = reason if isinstance(error, _Refused) else f"invalid YAML: {reason}"
        raise CurriculumError([Problem(file, line, "", message)]) from None
    finally:
        loader.dispose()
    if node is None or not isinstance(data, dict):
        found = "nothing" if data is None else f"a {type(data).__name__}"
        raise CurriculumError([Problem(file, None, "", f"the top level must be a mapping of keys, found {found}")])
    repeated = list(_repeated_keys(node, file, ()))
    if repeated:
        raise CurriculumError(repeated)
    return data, _key_lines(node, file, ())


def _repeated_keys(node: yaml.Node, file: Path | str, prefix: KeyPath) -> Iterator[Problem]:
    """A key written twice in one mapping: PyYAML would keep the second value without a word, so the
    setting a reader finds first would silently not be the one used."""
    if isinstance(node, yaml.MappingNode):
        first: dict[tuple[str, str], yaml.Node] = {}
        for key, value in node.value:
            if not isinstance(key, yaml.ScalarNode):
                continue
            earlier = first.setdefault((key.tag, key.value), key)
            if earlier is not key:
                message = f"set again here, after line {earlier.start_mark.line + 1}; delete one of the two"
                yield Problem(file, key.start_mark.line + 1, format_key(prefix + (key.value,)), message)
            yield from _repeated_keys(value, file, prefix + (key.value,))
    elif isinstance(node, yaml.SequenceNode):
        for index, item in enumerate(node.value):
            yield from _repeated_keys(item, file, prefix + (index,))


def _key_lines(node: yaml.Node, file: Path | str, prefix: KeyPath) -> Marks:
    marks: Marks = {}
    if isinstance(node, yaml.MappingNode):
        children = [((key.value,), key, value) for key, value in node.value if isinstance(key, yaml.ScalarNode)]
    elif isinstance(node, yaml.SequenceNode):
        children = [((index,), item, item) for index, item in enumerate(node.value)]
    else:
        return marks
    for step, marked, value in children:
        path = prefix + step
        marks[path] = _Mark(file, marked.start_mark.line + 1)
        marks.update(_key_lines(value, file, path))
    return marks


def _merge(parent: Any, child: Any) -> Any:
    if isinstance(parent, dict) and isinstance(child, dict):
        return {**parent, **{key: _merge(parent.get(key), value) for key, value in child.items()}}
    return child


def _replaced(path: KeyPath, parent: Any, child: Any) -> bool:
    """Whether the child replaces the parent's value at ``path`` or above it, so the parent's line for
    ``path`` no longer describes the merged data."""
    for key in path:
        if key not in child:
            return False
        parent, child = parent.get(key), child[key]
        if not (isinstance(parent, dict) and isinstance(child, dict)):
            return True
    return False


def given_by(label: str, paths: list[KeyPath]) -> Marks:
    """Marks for values that a command line gave rather than a file (``--set agent.critics=2``), so that a
    problem with one of them names the option that gave it."""
    return {path: _Mark(label, None) for path in paths}


def validate(model: type[Model], data: dict[str, Any], marks: Marks, file: Path | str) -> Model:
    """``data`` as ``model``, or a ``CurriculumError`` with every problem at the line that has it."""
    try:
        return model.model_validate(data)
    except ValidationError as error:
        raise CurriculumError([_problem(model, details, marks, file) for details in error.errors()]) from None


def _problem(root: type[BaseModel], details: ErrorDetails, marks: Marks, file: Path | str) -> Problem:
    loc = tuple(details["loc"])
    error = details.get("ctx", {}).get("error")
    if isinstance(error, KeyProblem):
        loc += error.key
    # The deepest key of the path that the file has: a missing key is reported at its parent.
    where = next((marks[loc[:end]] for end in range(len(loc), 0, -1) if loc[:end] in marks), _Mark(file, None))
    return Problem(where.file, where.line, format_key(loc), _message(root, details))


def format_key(loc: KeyPath) -> str:
    """``("stages", 0, "budget")`` as ``stages[0].budget``, as messages and ``--set`` name keys."""
    text = ""
    for key in loc:
        text += f"[{key}]" if isinstance(key, int) else f".{key}" if text else str(key)
    return text


def _message(root: type[BaseModel], details: ErrorDetails) -> str:
    kind, loc, value = details["type"], details["loc"], details["input"]
    if kind == "extra_forbidden":
        model = _model_at(root, loc[:-1])
        names = [] if model is None else list(model.model_fields) + ([EXTENDS] if model is root else [])
        close = difflib.get_close_matches(str(loc[-1]), names, n=1)
        return f"unknown key {loc[-1]!r}" + (f"; did you mean {close[0]!r}?" if close else "")
    if kind == "missing":
        return "required key is missing"
    if kind == "value_error":
        return str(details["ctx"]["error"])
    if isinstance(value, (str, int, float)):
        return f"{details['msg']}, got {value!r}"
    return details["msg"]


def _model_at(root: type[BaseModel], loc: KeyPath) -> type[BaseModel] | None:
    """The model that the data at ``loc`` is validated as, to list the keys it allows."""
    model: type[BaseModel] | None = root
    for key in loc:
        if isinstance(key, int):  # a list item: the model was already unwrapped from list[...]
            continue
        if model is None or key not in model.model_fields:
            return None
        model = _model_in(model.model_fields[key].annotation)
    return model


def _model_in(annotation: Any) -> type[BaseModel] | None:
    if typing.get_origin(annotation) is None and isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    return next((model for arg in typing.get_args(annotation) if (model := _model_in(arg))), None)
