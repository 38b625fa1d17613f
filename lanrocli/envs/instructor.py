"""The synthetic instructor: speaks the episode's instruction, watches the arm, and corrects it.

In a correction episode the instructor sets up one of the paper's misunderstandings (or simply waits for
the arm's own mistake). When the task condition holds for a non-goal object, it schedules a correction
after a delay of 0..max_delay steps; the correction then extends the goal sentence (g_l o g_ac). The goal
object never changes: reward is always for the object the instructor means, which is why achieving the
wrongly named object in an instruction correction episode does not end the episode.

With ``max_corrections`` above 1 the dialogue goes on while the arm keeps acting on yet another wrong
object: each further correction is appended to the sentence and singles out the goal among the candidates
not ruled out yet, as conversational repair continues until the misunderstanding is resolved.

With ``questions`` the agent may also ask "which one?" (:meth:`Instructor.answer`), before it acts or later. The
instructor answers honestly from what it believes: words that single out the object it means, appended to the
sentence as a correction is. In an instruction correction the speaker named the wrong object without knowing
it, so the answer names that object again and only a correction after the mistake can set the arm right.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from lanrocli.core.choices import CorrectionForm, Kind, Split
from lanrocli.envs.scene import Scene
from lanrocli.language import (
    BEGINNING_WORDS,
    NAMING_FORMS,
    TASK_VERBS,
    Phrase,
    check_task,
    correction,
    correction_forms,
    extend,
    instruction,
    max_sentence_words,
    pick,
)
from lanrocli.language.dialogue import candidates, naming_phrases, negation_phrases, opening_phrases
from lanrocli.language.holdout import NOTHING_HELD_OUT, Holdout
from lanrocli.language.paraphrase import Referents, paraphrase_correction
from lanrocli.tasks import task_class

MAX_DELAY = 20
"""Most steps a correction may wait after the mistake: later, the arm has long moved on."""

MAX_CORRECTIONS = 2
"""Most corrections in one episode: each needs a wrong object the arm has not been corrected on yet, and
a scene has at most three objects."""

PARAPHRASE_VERB_RATE = 0.5
"""Share of the paraphrase split's instructions spoken with a verb training never heard."""


@dataclass(frozen=True)
class InstructorSettings:
    """How often and how the instructor corrects; validated so a bad stage fails before any physics runs."""

    correction_rate: float = 0.0
    negations: bool = False
    max_delay: int = 0
    rare_words: bool = False
    kinds: tuple[Kind, ...] = tuple(Kind)
    max_corrections: int = 1
    """Most corrections in one episode (the paper: 1)."""
    questions: int = 0
    """Most questions the agent may ask in one episode. Each answer takes one of the ``max_corrections``
    places in the sentence, and where corrections are spoken one stays free, so that a correction can
    always follow an answer."""
    negation_rate: float | None = None
    """``None``: a correction's form is drawn uniformly among the allowed ones, as in the paper (a third are
    negations). A number: the share of corrections that are negations, wherever a negation can single out
    the goal; the rest are excuses and edits. A correction test sets it to measure negations with enough
    episodes to judge them."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.correction_rate <= 1.0:
            raise ValueError(f"correction_rate must be within [0, 1], got {self.correction_rate}")
        if not isinstance(self.max_delay, (int, np.integer)) or not 0 <= self.max_delay <= MAX_DELAY:
            raise ValueError(
                f"max_delay must be a whole number of steps within [0, {MAX_DELAY}], got {self.max_delay!r}"
            )
        try:
            kinds = tuple(Kind(k) for k in self.kinds)
        except ValueError:
            raise ValueError(f"kinds must be a subset of {[k.value for k in Kind]}, got {list(self.kinds)}") from None
        if not kinds:
            raise ValueError("kinds must name at least one kind of correction; leave it out to allow all kinds")
        repeated = sorted({kind.value for kind in kinds if kinds.count(kind) > 1})
        if repeated:
            raise ValueError(f"kinds names {', '.join(repeated)} more than once")
        object.__setattr__(self, "kinds", kinds)
        if not isinstance(self.max_corrections, (int, np.integer)) or not 1 <= self.max_corrections <= MAX_CORRECTIONS:
            raise ValueError(
                f"max_corrections must be a whole number within [1, {MAX_CORRECTIONS}], got {self.max_corrections!r}"
            )
        self._check_questions()
        if self.negation_rate is not None:
            if not 0.0 <= self.negation_rate <= 1.0:
                raise ValueError(f"negation_rate must be within [0, 1], got {self.negation_rate}")
            if self.negation_rate > 0 and self.correction_rate > 0 and not self.negations:
                raise ValueError(
                    f"negation_rate {self.negation_rate:g} needs negations=True: without them none is spoken"
                )
        if self.correction_rate > 0 and not self.active_kinds:
            raise ValueError("kinds=['common_ground'] needs rare_words=True: without rare words there is no such case")

    def _check_questions(self) -> None:
        if not isinstance(self.questions, (int, np.integer)) or self.questions < 0:
            raise ValueError(f"questions must be a whole number of at least 0, got {self.questions!r}")
        free = 1 if self.correction_rate > 0 else 0  # a correction must still fit after the answers
        if self.questions + free > self.max_corrections:
            after = ", and one must stay free for a correction after them" if free else ""
            raise ValueError(
                f"questions ({self.questions}) need room in the sentence: each answer takes one of max_corrections' "
                f"({self.max_corrections}) places{after}; raise max_corrections to {self.questions + free} or ask "
                "fewer questions"
            )

    @property
    def active_kinds(self) -> tuple[Kind, ...]:
        """The kinds this instructor can produce: common ground needs rare words to exist."""
        return tuple(k for k in self.kinds if k is not Kind.COMMON_GROUND or self.rare_words)


@dataclass(frozen=True)
class Correction:
    """A spoken correction, as reported in the environment's ``info``."""

    kind: Kind
    form: CorrectionForm
    text: str
    spoken_at: int
    triggered_at: int
    index: int = 1
    """Which correction of the episode this is: 1 for the first."""
    phrasing: str | None = None
    """The paraphrase it was spoken in (``lanrocli.language.paraphrase``), None for the grammar's words."""

    @property
    def negation(self) -> bool:
        return self.form is CorrectionForm.NEGATION

    def as_info(self) -> dict[str, object]:
        return {
            "kind": self.kind.value,
            "form": self.form.value,
            "negation": self.negation,
            "text": self.text,
            "spoken_at": self.spoken_at,
            "triggered_at": self.triggered_at,
            "index": self.index,
            "phrasing": self.phrasing,
        }


@dataclass(frozen=True)
class Answer:
    """The instructor's answer to a question, as reported in the environment's ``info["answers"]``."""

    text: str
    asked_at: int
    """The step at which the question was asked (0: before the arm's first move)."""
    referent: int
    """The object the answer names: the goal, or in an instruction correction the object the speaker
    believes they meant."""

    def as_info(self) -> dict[str, object]:
        return {"text": self.text, "asked_at": self.asked_at, "referent": self.referent}


@dataclass
class Instructor:
    """One episode's dialogue. ``start`` plans it; ``observe`` is called after every step."""

    task: str
    settings: InstructorSettings
    holdout: Holdout = NOTHING_HELD_OUT
    """What training never hears; with ``split``, the split whose episodes this instructor speaks in."""
    split: Split | None = None
    max_words: int | None = None
    """The most words the goal sentence may reach (the observation's L): a paraphrase is chosen only where
    it leaves room for the grammar's longest correction wherever another may follow."""
    challenge: Kind | None = field(default=None, init=False)
    instruction_text: str = field(default="", init=False)
    corrections: list[Correction] = field(default_factory=list, init=False)
    """The corrections spoken so far, in order."""
    answers: list[Answer] = field(default_factory=list, init=False)
    """The answers given to the agent's questions so far, in order."""
    _said: list[str] = field(default_factory=list, init=False)  # corrections and answers, in the order spoken
    _named: int | None = field(default=None, init=False)  # the object an instruction correction names
    fits: int = field(default=1, init=False)
    """How many objects the instruction may mean for a listener who knows only the common words: 1 where it
    singles one out (an instruction correction's too, though it is the wrong one), more where it is ambiguous
    or its rare colour word leaves the shape alone to go by."""
    _scene: Scene | None = field(default=None, init=False)
    _phrase: Phrase | None = field(default=None, init=False)
    _delay: int = field(default=0, init=False)
    _trigger: tuple[int, int] | None = field(default=None, init=False)  # (step, touched object)
    _corrected: set[int] = field(default_factory=set, init=False)  # the wrong objects already corrected on
    _rewording: np.random.Generator | None = field(default=None, init=False)
    """The paraphrase split's own draws, spawned from the episode's stream without advancing it, so its
    episodes and their control (the same seeds in the grammar) differ in the words alone."""
    _answering: np.random.Generator | None = field(default=None, init=False)
    """The answers' own draws, spawned like ``_rewording``: an episode with a question meets the same scene,
    delays and corrections as the same episode without one."""

    def __post_init__(self) -> None:
        check_task(self.task)
        self.holdout.check_split(self.split)

    @property
    def spoken(self) -> Correction | None:
        """The correction spoken last, or None before any."""
        return self.corrections[-1] if self.corrections else None

    @property
    def text(self) -> str:
        """The current goal sentence: the instruction, extended by each correction and answer spoken."""
        return extend(self.instruction_text, *self._said)

    def draw_challenge(self, rng: np.random.Generator) -> Kind | None:
        """Whether the next episode is a correction episode, and of which kind (drawn before the scene)."""
        if self.settings.correction_rate > 0 and rng.random() < self.settings.correction_rate:
            return pick(rng, self.settings.active_kinds)
        return None

    def start(self, rng: np.random.Generator, scene: Scene, challenge: Kind | None) -> None:
        self._scene, self.challenge, self._trigger = scene, challenge, None
        self.corrections, self.answers, self._said, self._corrected = [], [], [], set()
        first, last = self.holdout.delays(self.settings.max_delay, self.split)
        self._delay = int(rng.integers(first, last + 1))
        named = None
        if challenge is Kind.INSTRUCTION_CORRECTION:
            named = pick(rng, [i for i in range(len(scene.objects)) if i != scene.goal_index])
        self._named = named
        phrases = self.holdout.instruction_phrases(
            opening_phrases(challenge, scene.objects, scene.goal_index, named), self.split
        )
        if not phrases:
            name = challenge.value if challenge else "plain"
            raise RuntimeError(
                f"no {name} instruction exists for goal {scene.goal} among {scene.others(scene.goal_index)}"
            )
        self._phrase = pick(rng, phrases)
        self.instruction_text = instruction(pick(rng, TASK_VERBS[self.task]), self._phrase)
        if self.split is Split.PARAPHRASE:
            self._rewording = rng.spawn(1)[0]
            verbs = task_class(self.task).paraphrase_verbs
            if verbs and self._rewording.random() < PARAPHRASE_VERB_RATE:
                self.instruction_text = instruction(pick(self._rewording, verbs), self._phrase)
        self._answering = rng.spawn(1)[0] if self.settings.questions else None
        meant_one = challenge is None or challenge is Kind.INSTRUCTION_CORRECTION
        self.fits = 1 if meant_one else len(candidates(challenge, self._phrase, scene.objects))

    @property
    def can_answer(self) -> bool:
        """Whether the agent has a question left in this episode, and the sentence room for its answer."""
        return len(self.answers) < self.settings.questions and len(self._said) < self.settings.max_corrections

    @property
    def referent(self) -> int:
        """The object the speaker believes they mean: the goal, except in an instruction correction until
        its correction was spoken (the speaker has seen their mistake by then)."""
        assert self._scene is not None
        return self._scene.goal_index if self._named is None or self.corrections else int(self._named)

    def answer(self, step: int) -> Answer:
        """Answer "which one?" asked at ``step``: "actually the ..." with a phrase that fits the object the
        speaker means and no other object on the table (that object's full description always does)."""
        if not self.can_answer:
            raise RuntimeError(f"no question is left: {self.settings.questions} per episode were asked already")
        assert self._scene is not None and self._answering is not None
        objects, referent = self._scene.objects, self.referent
        everything = set(range(len(objects)))
        phrases = self.holdout.correction_phrases(naming_phrases(objects, referent, everything), self.split)
        text = correction(BEGINNING_WORDS[CorrectionForm.EDIT][0], pick(self._answering, phrases))
        given = Answer(text, step, referent)
        self.answers.append(given)
        self._said.append(text)
        return given

    def observe(self, rng: np.random.Generator, step: int, achieved: np.ndarray) -> bool:
        """Watch the state after ``step``; return True when the goal sentence changed at this step."""
        if self._trigger is None:
            wrong = self._uncorrected_mistakes(achieved)
            if not wrong:
                return False
            self._trigger = (step, int(pick(rng, wrong)))
            if self.corrections:  # each further correction waits a delay of its own
                first, last = self.holdout.delays(self.settings.max_delay, self.split)
                self._delay = int(rng.integers(first, last + 1))
        triggered_at, touched = self._trigger
        if step < triggered_at + self._delay:
            return False
        self._speak(rng, step, triggered_at, touched)
        return True

    def _uncorrected_mistakes(self, achieved: np.ndarray) -> list[int]:
        """The wrong objects the task holds for and no correction named yet, where one more may be spoken."""
        spoken = len(self.corrections) + len(self.answers)
        if self.challenge is None or spoken >= self.settings.max_corrections or self._scene is None:
            return []
        return [int(i) for i in np.flatnonzero(achieved) if i != self._scene.goal_index and i not in self._corrected]

    def _speak(self, rng: np.random.Generator, step: int, triggered_at: int, touched: int) -> None:
        spoken = self._correct(rng, step, triggered_at, touched)
        if self._rewording is not None:
            spoken = self._reworded(spoken, touched)
        self.corrections.append(spoken)
        self._said.append(spoken.text)
        self._corrected.add(touched)
        self._trigger = None

    def _reworded(self, spoken: Correction, touched: int) -> Correction:
        """``spoken`` in a phrasing of the paraphrase split, meaning what it meant: it counts as its form."""
        assert self._scene is not None and self.challenge is not None and self._phrase is not None
        objects = self._scene.objects
        considered = candidates(self.challenge, self._phrase, objects) - self._corrected
        referents = Referents(
            objects, self._scene.goal_index, touched, considered, lambda ps: self.holdout.correction_phrases(ps, None)
        )
        assert self._rewording is not None
        later = self.settings.max_corrections - len(self._said) - 1  # corrections that may follow
        longest = max_sentence_words(1) - max_sentence_words(0)
        room = None if self.max_words is None else self.max_words - len(self.text.split()) - later * longest
        reworded = paraphrase_correction(self._rewording, spoken.form, referents, room)
        return spoken if reworded is None else replace(spoken, text=reworded[0], phrasing=reworded[1])

    def _form(self, rng: np.random.Generator) -> CorrectionForm:
        rate = self.settings.negation_rate
        if rate is None or not self.settings.negations:
            return pick(rng, correction_forms(self.settings.negations))
        return CorrectionForm.NEGATION if rng.random() < rate else pick(rng, NAMING_FORMS)

    def _correct(self, rng: np.random.Generator, step: int, triggered_at: int, touched: int) -> Correction:
        assert self._scene is not None and self.challenge is not None and self._phrase is not None
        objects, goal = self._scene.objects, self._scene.goal_index
        considered = candidates(self.challenge, self._phrase, objects) - self._corrected
        index = len(self.corrections) + 1
        form = self._form(rng)
        if form is CorrectionForm.NEGATION:
            negations = self.holdout.correction_phrases(
                negation_phrases(objects, goal, touched, considered), self.split
            )
            if negations:
                text = correction(BEGINNING_WORDS[form][0], pick(rng, negations))
                return Correction(self.challenge, form, text, step, triggered_at, index)
            form = pick(rng, NAMING_FORMS)
        naming = self.holdout.correction_phrases(naming_phrases(objects, goal, considered), self.split)
        text = correction(pick(rng, BEGINNING_WORDS[form]), pick(rng, naming))
        return Correction(self.challenge, form, text, step, triggered_at, index)
