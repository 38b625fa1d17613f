"""Registries: entries in order, refused clashes, registrations that end with their block, live views."""

from __future__ import annotations

import pytest

from lanrocli.core.registry import Live, Registry
from lanrocli.tasks import Reach, TaskDefinition, register


def test_entries_keep_their_order_and_a_taken_name_is_refused() -> None:
    registry: Registry[str] = Registry("word", lambda word: word)
    names = registry.names
    for word in ("b", "a", "c"):
        registry.register(word)
    assert list(registry) == ["b", "a", "c"] and names == ("b", "a", "c") and registry.by_name["a"] == "a"
    with pytest.raises(ValueError, match="'a' is registered already"):
        registry.register("a")
    registry.unregister("a")
    assert names == ["b", "c"]
    with pytest.raises(ValueError, match=r"word must be one of \['b', 'c'\], got 'a'"):
        registry.unregister("a")


def test_a_registration_ends_with_its_block_even_on_an_error() -> None:
    registry: Registry[str] = Registry("word", lambda word: word)
    with pytest.raises(RuntimeError), registry.registered("a"):
        assert "a" in registry.names
        raise RuntimeError
    assert len(registry) == 0


def test_a_live_view_is_computed_when_read() -> None:
    source = [1, 2]
    view = Live(lambda: tuple(source))
    source.append(3)
    assert view == (1, 2, 3) and view[-1] == 3 and len(view) == 3 and view != (1, 2)


def test_a_task_class_without_verbs_or_with_a_taken_id_is_refused() -> None:
    class Silent(TaskDefinition):
        name, gym_id, verbs = "silent", "lanro/Silent-v0", ()

    class Twin(TaskDefinition):
        name, gym_id, verbs = "twin", Reach.gym_id, ("twin",)

    class Nameless(TaskDefinition):
        verbs = ("do",)

    with pytest.raises(TypeError, match="no verbs"):
        register(Silent)
    with pytest.raises(ValueError, match="lanro/Reach-v0 of task 'reach'"):
        register(Twin)
    with pytest.raises(TypeError, match="does not set name, gym_id"):
        register(Nameless)
