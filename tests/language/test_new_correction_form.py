"""The recipe "add a correction form" of docs/architecture.md, followed on a copy of the package: a new form that
names the goal ("instead the green cube"), added as the recipe says, and what follows from it checked in a
process that imports the copy. A form is a member of an enum that modules read when they load, so the recipe
is carried out on the source, as a researcher would, not patched into a running process."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import lanrocli

CHECK = textwrap.dedent(
    """
    import numpy as np

    from lanrocli.core.choices import CorrectionForm, Kind, Mode
    from lanrocli.envs.instructor import Instructor, InstructorSettings
    from lanrocli.envs.scene import Scene, sample_objects
    from lanrocli.evaluation.metrics import METRIC_NAMES
    from lanrocli.language import UNK_ID, grammar_vocabulary
    from lanrocli.language.typed import Grammar, Utterance

    form = CorrectionForm("instead")
    vocabulary, grammar = grammar_vocabulary(), Grammar.of("push")
    spoken_in_form = 0
    for seed in range(1000):
        rng = np.random.default_rng(seed)
        kind = list(Kind)[seed % len(Kind)]
        settings = InstructorSettings(correction_rate=1.0, negations=False, rare_words=True, kinds=(kind,))
        instructor = Instructor("push", settings)
        objects, goal = sample_objects(
            rng, Mode.COLOUR_SHAPE, 3, need_shared=kind is Kind.AMBIGUITY, need_same_shape=kind is Kind.COMMON_GROUND
        )
        scene = Scene(objects, goal, np.zeros((3, 2)))
        instructor.start(rng, scene, instructor.draw_challenge(rng))
        first = instructor.text
        wrong = int(rng.choice([i for i in range(3) if i != goal]))
        achieved = np.zeros(3, dtype=bool)
        for step in range(1, 30):
            achieved[wrong] = step >= 5
            instructor.observe(rng, step, achieved)
        spoken = instructor.spoken
        if spoken is None or spoken.form is not form:
            continue
        spoken_in_form += 1
        assert spoken.text.startswith("instead the "), spoken.text
        assert UNK_ID not in vocabulary.encode(instructor.text), instructor.text
        said = Utterance(tuple(first.split()), tuple(spoken.text.split()))
        assert said in grammar, instructor.text
        assert said.fitting(scene.objects) == [scene.goal_index], (instructor.text, scene.objects)
    assert spoken_in_form > 100, spoken_in_form
    assert "corrected_success_instead" in METRIC_NAMES
    print("spoken", spoken_in_form)
    """
)


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert text.count(old) == 1, f"{path}: the recipe's anchor {old!r} is not there once"
    path.write_text(text.replace(old, new))


def test_a_form_added_as_the_recipe_says_is_spoken_read_and_measured(tmp_path: Path) -> None:
    package = tmp_path / "lanrocli"
    shutil.copytree(Path(lanrocli.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__"))
    # 1. The member, at the end of CorrectionForm.
    _edit(package / "core" / "choices.py", '    EDIT = "edit"\n', '    EDIT = "edit"\n    INSTEAD = "instead"\n')
    # 2. Its opening words; a form that names the goal goes into NAMING_FORMS; its new word gets the next id.
    grammar = package / "language" / "grammar.py"
    _edit(
        grammar,
        '    CorrectionForm.EDIT: ("actually",),\n',
        '    CorrectionForm.EDIT: ("actually",),\n    CorrectionForm.INSTEAD: ("instead",),\n',
    )
    _edit(
        grammar,
        "(CorrectionForm.EXCUSE, CorrectionForm.EDIT)",
        "(CorrectionForm.EXCUSE, CorrectionForm.EDIT, CorrectionForm.INSTEAD)",
    )
    words = package / "language" / "word_ids.txt"
    words.write_text(words.read_text() + "instead\n")
    # 3. Every correction spoken in the new form singles out the goal, and evaluation measures the form.
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    result = subprocess.run([sys.executable, "-c", CHECK], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "spoken" in result.stdout
