"""``lanro play``: a person gives a trained agent its instructions, and may correct it while it acts.

The environment draws the scene and runs the physics, but the sentence the agent reads is the person's,
not the instructor's, and so is the object success is judged on: each typed line is read the way the
instructor builds its sentences (an instruction, then a correction appended to it) to find the object the
sentence singles out (:mod:`lanrocli.language.typed`). A person types what they like, so a sentence outside the
grammar is read all the same (and flagged), and a word outside the vocabulary is read as ``<unk>`` (and named),
as the agent sees it.

One protocol serves a terminal (with prompts) and a pipe (one line per read), so a script of lines plays
the same episodes as a person typing them:

1. An episode's scene is drawn (episode i uses seed ``seed + i - 1``) and its objects are shown; the next
   line is the instruction.
2. The agent acts ``steps_per_line`` steps, then the next line is read: text is a correction, appended to
   the sentence, after any earlier one, as long as the whole still fits the sentences the agent reads
   (an agent trained with ``max_corrections`` above 1 reads chains of them); an empty line lets the agent
   go on. Once the input has
   ended, no line is waited for.
3. The episode ends when the task holds for the object the sentence singles out, at the step limit, or
   when that object falls off the table.
4. The next line is the next episode's instruction, until the input ends or ``episodes`` were played.

With ``questions`` (``--questions 1``) the agent may ask "which one?" where its attention, read by the rule
its question test calibrates (:mod:`lanrocli.evaluation.asking`), keeps other than exactly one object: the
question names the objects it keeps, and the next line is the person's answer, appended to the sentence as
a correction is. The question takes no step here: the scene waits for the person.

An instruction that cannot be read (an empty line, or more words than the agent reads) is asked for again
in a terminal; from a pipe, where every later line would be misread, it ends play with a ``PlayError``.
Empty lines between episodes are skipped, though: they are the "go on" lines of an episode that ended
sooner than its script expected.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import pybullet
from rich.console import Console
from rich.markup import escape

from lanrocli.agent.policy import AgentPolicy
from lanrocli.envs.caption import caption
from lanrocli.envs.env import IMAGE_SIZE, LanroEnv
from lanrocli.envs.settings import CORRECTION_LIMIT, EnvSettings
from lanrocli.evaluation.asking import kept
from lanrocli.evaluation.evaluate import save_gif
from lanrocli.language import TASK_VERBS, ObjectProps
from lanrocli.language.typed import Grammar, Utterance, unknown_words, words_of
from lanrocli.language.vocabulary import UNK
from lanrocli.pretrained import agent_path
from lanrocli.sim import CONTROL_DT, action_size
from lanrocli.tasks import FALLEN, Task, task_class
from lanrocli.train.errors import CheckpointError
from lanrocli.train.trainer import load_policy, pick_device


class PlayError(Exception):
    """Something the person can put right (a checkpoint, an option, a line), said in words, not a traceback."""


def name(obj: ObjectProps) -> str:
    return f"{obj.colour} {obj.shape}"


def names(objects: Sequence[ObjectProps]) -> str:
    return ", ".join(name(o) for o in objects) or "nothing"


@dataclass(frozen=True)
class PlayOptions:
    """What ``lanro play`` was asked for besides the checkpoint; ``overrides`` are ``EnvSettings`` fields."""

    task: Task | None = None
    overrides: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    episodes: int | None = None
    steps_per_line: int = 10
    gif: Path | None = None
    gui: bool = False
    device: str | None = None


@dataclass(frozen=True)
class Outcome:
    """How one episode went: the last sentence, the object it singled out, success and its length."""

    sentence: str
    target: ObjectProps | None
    success: bool
    steps: int
    gif: Path | None


class Lines:
    """The person's lines: from a terminal, each after a prompt; from a pipe, one per read. ``None`` once
    the input has ended, and from then on without reading again."""

    def __init__(self, stream: TextIO, console: Console) -> None:
        self.stream = stream
        self.console = console
        self.interactive = stream.isatty()
        self.ended = False
        self._ahead: str | None = None

    def more(self) -> bool:
        """Whether another instruction may come, asked between episodes. A pipe is read ahead to its next
        line that is not empty, so that no new scene is shown for a script that has ended: the empty lines
        skipped are the "go on" lines of an episode that ended sooner than its script expected. A terminal
        may always bring one until it is closed."""
        while not self.interactive and not self.ended and not (self._ahead or "").strip():
            self._ahead = self._from_pipe()
        return not self.ended

    def read(self, prompt: str) -> str | None:
        if self._ahead is not None:
            line, self._ahead = self._ahead, None
            return line
        if self.ended:
            return None
        if not self.interactive:
            return self._from_pipe()
        try:
            return self.console.input(f"[bold]{escape(prompt)}>[/] ")
        except EOFError:
            self.console.print()
            self.ended = True
            return None

    def _from_pipe(self) -> str | None:
        line = self.stream.readline()
        if not line:
            self.ended = True
            return None
        return line.rstrip("\r\n")


def check_display(environ: Mapping[str, str] = os.environ, platform: str = sys.platform) -> None:
    """Refuse ``--gui`` where PyBullet could not open its window: on Linux without an X display, its GUI
    client ends the whole process from C code, which no Python handler can turn into a message."""
    if platform.startswith("linux") and not environ.get("DISPLAY"):
        raise PlayError(
            "--gui opens PyBullet's window, and there is no display here (DISPLAY is not set); "
            "leave out --gui, and use --gif DIR to watch the episodes afterwards"
        )


def load_agent(path: Path, options: PlayOptions) -> tuple[str, EnvSettings, int, AgentPolicy]:
    """The task, environment settings, object slots and policy to play with: the checkpoint's stage as
    evaluation sees it, changed by the options. Episodes last as long as correction episodes (unless
    ``max_episode_steps`` says otherwise), since any of them may be corrected."""
    try:
        device = pick_device(options.device)
    except ValueError as error:
        raise PlayError(str(error)) from None
    try:
        settings, policy = load_policy(agent_path(path), device)
    except (CheckpointError, KeyError, TypeError, ValueError) as error:
        raise PlayError(f"cannot load a trained agent from {path}: {error}") from None
    task = options.task or settings.task
    trained, asked = (action_size(task_class(name).gripper) for name in (settings.task, task))
    if trained != asked:
        raise PlayError(f"{path} was trained on {settings.task} ({trained} actions); {task} needs {asked} actions")
    try:
        env = settings.env.for_evaluation().replace(**options.overrides)
        env = env.replace(max_episode_steps=env.max_episode_steps or CORRECTION_LIMIT)
    except ValueError as error:
        raise PlayError(str(error)) from None
    if env.objects > settings.slots:
        raise PlayError(f"{path} observes at most {settings.slots} objects; --objects must not exceed that")
    return task, env, settings.slots, policy


def play(path: Path, options: PlayOptions, stream: TextIO, console: Console) -> list[Outcome]:
    """Play episodes with the agent at ``path`` (a checkpoint, a pointer or a run folder) as the lines of
    ``stream`` say; raises ``PlayError`` for anything the person should put right."""
    if options.gui:
        check_display()
    if options.gif is not None and options.gif.exists() and not options.gif.is_dir():
        raise PlayError(f"--gif {options.gif} is a file; give a folder, where episode-1.gif, ... are written")
    task, settings, slots, policy = load_agent(path, options)
    try:
        env = LanroEnv(
            task,
            settings,
            object_slots=slots,
            render_mode=None if options.gif is None else "rgb_array",
            gui=options.gui,
            vocabulary=policy.vocabulary,
        )
    except pybullet.error as error:
        raise PlayError(f"PyBullet could not open its window: {error}") from None
    threshold = None
    if settings.questions:
        from lanrocli.train.testset import calibrated_rule

        try:
            threshold = calibrated_rule(agent_path(path), pick_device(options.device)).threshold
        except ValueError as error:
            raise PlayError(f"--questions: the agent's rule for asking cannot be calibrated here: {error}") from None
    try:
        return Session(env, policy, Lines(stream, console), console, options, threshold).run()
    finally:
        env.close()


class Session:
    """The episodes of one agent in one environment, as the person's lines drive them."""

    def __init__(
        self,
        env: LanroEnv,
        policy: AgentPolicy,
        lines: Lines,
        console: Console,
        options: PlayOptions,
        threshold: float | None = None,
    ) -> None:
        self.env = env
        self.threshold = threshold
        """The calibrated rule's threshold where the agent may ask (``questions``), else None."""
        self.policy = policy
        self.lines = lines
        self.console = console
        self.options = options
        self.vocabulary = policy.vocabulary
        self.grammar = Grammar.of(env.task.name)

    def say(self, text: str, style: str | None = None) -> None:
        self.console.print(text, style=style, markup=False, highlight=False)

    def warn(self, text: str) -> None:
        self.console.print(f"[bold yellow]warning:[/] {escape(text)}", highlight=False)

    def run(self) -> list[Outcome]:
        outcomes: list[Outcome] = []
        while (self.options.episodes is None or len(outcomes) < self.options.episodes) and (
            not outcomes or self.lines.more()
        ):
            number = len(outcomes) + 1
            observation, info = self.env.reset(seed=self.options.seed + number - 1)
            objects = tuple(info["objects"])
            self.say(f"episode {number}: on the table: {names(objects)}", style="bold")
            utterance = self._instruction(objects, first=not outcomes)
            if utterance is None:
                break
            outcomes.append(self._episode(number, observation, info, utterance))
        if outcomes:
            won = sum(o.success for o in outcomes)
            self.say(
                f"{len(outcomes)} episode{'s' if len(outcomes) > 1 else ''}, {won} success{'es' if won != 1 else ''}"
            )
        return outcomes

    def _instruction(self, objects: Sequence[ObjectProps], first: bool) -> Utterance | None:
        """The next readable instruction, or None when the input ends (an error before the first one)."""
        hint = f"type an instruction such as '{TASK_VERBS[self.env.task.name][0]} the {name(objects[0])}'"
        while True:
            line = self.lines.read("instruction")
            if line is None:
                if first:
                    raise PlayError(f"the input ended before any instruction; {hint}")
                return None
            words = words_of(line)
            if words and len(words) <= self.vocabulary.max_length:
                return Utterance(words)
            if words:
                problem = f"'{line}' has {len(words)} words, and the agent reads at most {self.vocabulary.max_length}"
            else:
                problem = f"an empty line is no instruction; {hint}"
            if not self.lines.interactive:
                raise PlayError(problem)
            self.warn(problem)

    def _heard(self, utterance: Utterance, words: Sequence[str], objects: Sequence[ObjectProps]) -> int | None:
        """Tell the person how the agent reads what they just said, and return the object it singles out."""
        for word in unknown_words(words, self.vocabulary):
            self.warn(f"unknown word '{word}' read as {UNK}")
        if utterance not in self.grammar:
            self.warn(
                f"'{utterance.text}' is outside the grammar of {self.grammar.task} instructions and corrections "
                "the agent was trained on; it reads it all the same"
            )
        fitting = utterance.fitting(objects)
        if len(fitting) == 1:
            self.say(f"goal: the {name(objects[fitting[0]])}")
            return fitting[0]
        if fitting:
            what = f"it fits the {' and the '.join(name(objects[i]) for i in fitting)}"
        else:
            what = f"it fits nothing on the table ({names(objects)})"
        self.warn(f"the sentence singles out no object: {what}; success is judged once a correction names one")
        return None

    def _episode(
        self, number: int, observation: dict[str, np.ndarray], info: dict[str, Any], utterance: Utterance
    ) -> Outcome:
        objects = tuple(info["objects"])
        target = self._heard(utterance, utterance.instruction, objects)
        tokens = self.vocabulary.encode(utterance.text)
        frames = [self._frame(utterance)] if self.options.gif else None
        steps, limit = 0, self.env.max_episode_steps
        questions = self.env.settings.questions
        asks = np.full(1 if questions else 0, -1.0)  # the person answers here, not the environment's instructor
        while True:
            for _ in range(self.options.steps_per_line):
                if questions and (asked := self._question(observation, tokens, utterance, objects)) is not None:
                    questions -= 1
                    if asked:
                        utterance = utterance.corrected(asked)
                        target = self._heard(utterance, asked, objects)
                        tokens = self.vocabulary.encode(utterance.text)
                action = self.policy.act({**observation, "instruction": tokens}, info)
                observation, _, _, _, info = self.env.step(np.concatenate([action, asks]))
                steps += 1
                if frames is not None:
                    frames.append(self._frame(utterance))
                if self.options.gui:
                    time.sleep(CONTROL_DT)
                self._show_step(steps, utterance, observation, info, target)
                success = target is not None and bool(info["achieved"][target])
                fallen = target is not None and bool(info["object_positions"][target, 2] < FALLEN)
                if success or fallen or steps >= limit:
                    return self._end(number, utterance, objects, target, success, fallen, steps, frames)
            line = self.lines.read("correction, or Enter to go on")
            if line and (words := words_of(line)):
                corrected = utterance.corrected(words)
                if corrected.length > self.vocabulary.max_length:
                    self.warn(
                        f"'{corrected.text}' would have {corrected.length} words, and the agent reads at most "
                        f"{self.vocabulary.max_length}: correction not given"
                    )
                    continue
                utterance = corrected
                self.say(f"correction at step {steps}: the agent now reads '{utterance.text}'")
                target = self._heard(utterance, words, objects)
                tokens = self.vocabulary.encode(utterance.text)

    def _question(
        self,
        observation: dict[str, np.ndarray],
        tokens: np.ndarray,
        utterance: Utterance,
        objects: Sequence[ObjectProps],
    ) -> list[str] | None:
        """Where the rule asks on the sentence the agent reads now, the question put to the person and the
        words of their answer, empty where none fits (no answer, or too long to read); None where the rule
        does not ask."""
        assert self.threshold is not None
        shown = {key: value[None] for key, value in {**observation, "instruction": tokens}.items()}
        _, weights = self.policy.act_batch(shown)
        assert weights is not None
        keep = np.flatnonzero(kept(weights[0][: len(objects)], self.threshold))
        if len(keep) == 1:
            return None
        choices = " or ".join(f"the {name(objects[i])}" for i in (keep if len(keep) else range(len(objects))))
        self.say(f"the agent asks: which one: {choices}?", style="bold")
        words = words_of(self.lines.read("answer") or "")
        if not words:
            self.say("no answer: the agent acts on its own reading")
            return []
        answered = utterance.corrected(words)
        if answered.length > self.vocabulary.max_length:
            self.warn(f"'{answered.text}' would have {answered.length} words, more than the agent reads: not given")
            return []
        self.say(f"answer: the agent now reads '{answered.text}'")
        return words

    def _frame(self, utterance: Utterance) -> np.ndarray:
        """The camera image captioned with the person's sentence (the environment's own would show the
        instructor's, which the agent does not read here)."""
        return caption(self.env.world.render(*IMAGE_SIZE), utterance.text)

    def _show_step(
        self,
        step: int,
        utterance: Utterance,
        observation: dict[str, np.ndarray],
        info: dict[str, Any],
        target: int | None,
    ) -> None:
        objects = info["objects"]
        held = [objects[i] for i in np.flatnonzero(info["achieved"])]
        line = f"step {step:3d}  '{utterance.text}'  task holds for: {names(held)}"
        if target is not None:
            hand = observation["observation"][:3]
            distance = float(np.linalg.norm(info["object_positions"][target] - hand))
            line += f"  goal {name(objects[target])}, {100 * distance:.1f} cm from the hand"
        self.say(line)

    def _end(
        self,
        number: int,
        utterance: Utterance,
        objects: Sequence[ObjectProps],
        target: int | None,
        success: bool,
        fallen: bool,
        steps: int,
        frames: list[np.ndarray] | None,
    ) -> Outcome:
        goal = None if target is None else objects[target]
        if success and goal is not None:
            self.say(
                f"episode {number}: success at step {steps}: the task holds for the {name(goal)}", style="bold green"
            )
        else:
            why = "the goal fell off the table" if fallen else "the step limit"
            if goal is None:
                why += "; the sentence singled out no object"
            self.say(f"episode {number}: no success in {steps} steps ({why})", style="bold red")
        gif = None
        if frames is not None and self.options.gif is not None:
            gif = self.options.gif / f"episode-{number}.gif"
            try:
                save_gif(frames, gif, self.env.metadata["render_fps"])
            except OSError as error:
                raise PlayError(f"cannot write {gif}: {error.strerror or error}") from None
            self.say(f"wrote {gif}")
        return Outcome(utterance.text, goal, success, steps, gif)
