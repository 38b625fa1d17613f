"""EnvSettings: the one place that checks an environment's settings, and what reads them."""

from __future__ import annotations

import json

import pytest

from lanrocli.core.choices import Kind, Mode
from lanrocli.envs.settings import CORRECTION_LIMIT, PLAIN_LIMIT, EnvSettings


@pytest.mark.parametrize(
    "changes, setting",
    [
        ({"objects": 4}, "objects"),
        ({"objects": True}, "objects"),
        ({"mode": "weird"}, "mode"),
        ({"correction_rate": -0.1}, "correction_rate"),
        ({"max_delay": 21}, "max_delay"),
        ({"kinds": ("gossip",)}, "kinds"),
        ({"kinds": ()}, "kinds"),
        ({"kinds": ("ambiguity", "ambiguity")}, "kinds"),
        ({"max_episode_steps": 0}, "max_episode_steps"),
        ({"random_start": 1.5}, "random_start"),
        ({"object_start": -0.5}, "object_start"),
        ({"object_start": 0.6, "random_start": 0.5}, "object_start"),
    ],
)
def test_each_bad_setting_is_named(changes: dict, setting: str) -> None:
    with pytest.raises(ValueError, match=setting):
        EnvSettings(**changes)


def test_checks_across_settings_are_the_instructors() -> None:
    EnvSettings(kinds=("common_ground",))  # no corrections: nothing to produce
    with pytest.raises(ValueError, match="rare_words"):
        EnvSettings(correction_rate=0.5, kinds=("common_ground",))


def test_values_become_their_enums() -> None:
    settings = EnvSettings(mode="shape", kinds=("wrong_object",))
    assert settings.mode is Mode.SHAPE and settings.kinds == (Kind.WRONG_OBJECT,)


def test_plain_data_round_trips_through_json() -> None:
    settings = EnvSettings(objects=3, mode=Mode.COLOUR_SHAPE, correction_rate=0.5, kinds=(Kind.AMBIGUITY,))
    data = json.loads(json.dumps(settings.to_dict()))
    assert data["mode"] == "colour_shape" and data["kinds"] == ["ambiguity"]
    assert EnvSettings(**data) == settings


def test_episode_limit_and_evaluation_view() -> None:
    assert EnvSettings().episode_limit == PLAIN_LIMIT
    assert EnvSettings(correction_rate=0.5).episode_limit == CORRECTION_LIMIT
    assert EnvSettings(correction_rate=0.5, max_episode_steps=30).episode_limit == 30
    training = EnvSettings(objects=3, max_corrections=2, random_start=0.5, object_start=0.25, mistake_start=0.5)
    assert training.for_evaluation() == EnvSettings(objects=3, max_corrections=2)
    assert training.for_evaluation(correction_rate=1.0) == EnvSettings(objects=3, max_corrections=2)  # none to raise
    corrections = EnvSettings(correction_rate=0.5, random_start=0.5)
    assert corrections.for_evaluation(correction_rate=1.0) == EnvSettings(correction_rate=1.0)
    assert corrections.for_evaluation() == EnvSettings(correction_rate=0.5)
