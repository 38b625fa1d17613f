"""``LanroEnv``: the Panda, a scene, a task and the instructor, as one gymnasium environment."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from lanrocli.core.choices import Kind, Split
from lanrocli.core.reward import reward
from lanrocli.envs.instructor import Instructor
from lanrocli.envs.scene import Scene, check_scenes, sample_scene
from lanrocli.envs.settings import EnvSettings
from lanrocli.envs.starts import place_arm
from lanrocli.language import COLOURS, SHAPES, Vocabulary, grammar_vocabulary, max_sentence_words
from lanrocli.language.holdout import NOTHING_HELD_OUT, Holdout
from lanrocli.sim import (
    MAX_STEP,
    OBJECT_AREA,
    ObjectSet,
    Panda,
    World,
    action_size,
    resting_position,
)
from lanrocli.sim import (
    SHAPES as SIM_SHAPES,
)
from lanrocli.tasks import FALLEN, ArmView, OracleMemory, TaskView, make_task

ARM_SIZE = 7
"""End-effector position (3), its linear velocity (3), finger width (1)."""

OBJECT_SIZE = 3 + 3 + 3 + 4 + 3 + 3 + len(COLOURS) + len(SHAPES)
"""Per object: position (3), position relative to the end effector (3), displacement since the episode
began (3), quaternion x y z w (4), linear (3) and angular (3) velocity, one-hot colour and shape."""

MIN_SPACING_SIZES = 3.0
"""Objects start at least this many object sizes apart."""

IMAGE_SIZE = (480, 360)

MISTAKE_STEPS = 40
"""Most steps the scripted oracle is given to do the task on a wrong object at a mistake start (it needs 10
to 20); a start whose oracle has not finished by then begins where it got to."""


def observation_size(n_objects: int) -> int:
    return ARM_SIZE + n_objects * OBJECT_SIZE


class LanroEnv(gym.Env[dict[str, np.ndarray], np.ndarray]):
    """A Panda on a table with 2 or 3 objects and an instructor that speaks, watches and corrects.

        Observation ``{"observation": float32[N], "instruction": int64[L]}`` with N = 7 + 31 ``object_slots``
        (by default the number of objects; a curriculum whose stages differ in objects gives every stage the
        largest number, so one network reads them all, and the slots without an object are zeros):

        - ``[0:3]`` end-effector position (m), ``[3:6]`` its velocity (m/s), ``[6]`` finger width (m);
        - per object k (in the order of ``info["objects"]``), from ``7 + 31 k``: position (3), position minus
          the end-effector position (3), position minus the position at reset (3), orientation quaternion
          x y z w (4), linear velocity (3), angular velocity (3), one-hot colour (9, in the order of
          ``lanrocli.language.COLOURS``), one-hot shape (3, ``cube cuboid cylinder``).

        The displacement since reset is what lets the observation tell how far an object has moved: reach on an
        object fails once it was knocked more than 2.5 cm, and push succeeds once its object slid far enough,
        both measured from where the objects started. Without it, a knocked object at rest looks like an
        untouched one, and a random arm knocks one in about a fifth of its reach episodes, after which touching
        it earns -1 in states the critic cannot tell from those where it earns 0. The relative position is
        redundant but not idle: what every task needs first is the offset from the hand to the named object.

        How far push must slide its object and how high lift must raise it are drawn per episode
        (``lanrocli.tasks``) and are not observed: the instruction names no distance, so the agent is not
        told them and has to learn to go past the largest distance or height an episode may draw. For push and
        lift the reward is therefore not a function of the observation alone.

        Episodes start with the end effector at (0, 0, 0.10); ``random_start`` is the share that starts at a
        random point of the workspace near the table instead, clear of the objects, ``object_start`` (grasp
        and lift) the share that starts with the open hand around a random object, and ``mistake_start`` the
        share that starts with the task just done on a wrong object (all for training).

        ``instruction`` is the current goal sentence (instruction, plus the correction from the step it is
        spoken) as token ids of ``vocabulary`` (by default the grammar's; an agent's own when one is run),
        padded with 0. Reward is 0 when the task holds for the goal
        object, else -1; success ends the episode (terminated), and so does the goal falling off the table
        (truncated, with ``info["fell"]``: the episode is lost, not merely out of time); another object may
        fall to the floor and the episode goes on. ``info`` carries
        ``is_success``, ``achieved`` (per object), ``goal_index``, ``object_positions``, ``objects`` (``ObjectProps``
        in observation order), ``instruction_text``,
        ``challenge`` (the ``Kind`` of misunderstanding of a correction episode, or ``None``), ``correction``
        (``None`` until spoken), ``referent`` (the object the speaker believes they mean: the goal, except in an
        instruction correction), ``fits`` (how many objects the instruction may mean to a listener who knows only
    the common words), ``asked`` (whether this step was a question) and ``answers`` (the instructor's
        answers so far; see ``step``).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(
        self,
        task: str = "reach",
        settings: EnvSettings | None = None,
        *,
        object_slots: int | None = None,
        render_mode: str | None = None,
        gui: bool = False,
        vocabulary: Vocabulary | None = None,
        holdout: Holdout = NOTHING_HELD_OUT,
        split: Split | None = None,
        time_limit: bool = True,
        **changes: Any,
    ) -> None:
        """``settings`` (default: ``EnvSettings()``), with any of its fields changed by keyword, as
        ``gymnasium.make("lanro/Push-v0", objects=3)`` passes them. ``holdout``: what the episodes never
        contain, except, with ``split``, the part held out for that generalisation split.

        ``time_limit=False`` leaves truncation by steps to a ``gymnasium.wrappers.TimeLimit`` around the
        environment (``max_episode_steps`` is then None): ``gymnasium.make`` adds one with the limit asked
        of it and never passes that limit here, so the registered ids make their environments this way."""
        settings = (settings or EnvSettings()).replace(**changes)
        slots = settings.objects if object_slots is None else object_slots
        if slots < settings.objects:
            raise ValueError(f"object_slots ({slots}) must be at least objects ({settings.objects})")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.settings = settings
        self.task = make_task(task)
        settings.check_task(self.task.name)
        self.n_objects = objects = settings.objects
        self.object_slots = slots
        self.render_mode = render_mode
        self.max_episode_steps = settings.episode_limit if time_limit else None
        self.vocabulary = vocabulary if vocabulary is not None else grammar_vocabulary(settings.max_corrections)
        longest = max_sentence_words(settings.max_corrections)
        if self.vocabulary.max_length < longest:
            raise ValueError(
                f"sentences of up to {settings.max_corrections} corrections have up to {longest} words, and this "
                f"vocabulary encodes at most {self.vocabulary.max_length}: lower max_corrections, or use an agent "
                "trained to read that many"
            )
        n = observation_size(slots)
        self.observation_space = gym.spaces.Dict(
            {
                "observation": gym.spaces.Box(-np.inf, np.inf, shape=(n,), dtype=np.float32),
                "instruction": gym.spaces.Box(
                    0, len(self.vocabulary) - 1, shape=(self.vocabulary.max_length,), dtype=np.int64
                ),
            }
        )
        self.arm_actions = action_size(self.task.gripper)
        asks = 1 if settings.questions else 0
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(self.arm_actions + asks,), dtype=np.float32)

        self.world = World(gui=gui, images=gui or render_mode is not None)
        self.robot = Panda(self.world, gripper=self.task.gripper)
        self.objects = ObjectSet(self.world)
        split = None if split is None else Split(split)
        check_scenes(settings.mode, objects, holdout, split)
        self.holdout, self.split = holdout, split
        self.instructor = Instructor(self.task.name, settings.instructor, holdout, split, self.vocabulary.max_length)
        self._scene: Scene | None = None
        self._start_positions = np.zeros((objects, 3))
        self._heights = np.zeros(objects)
        self._properties = np.zeros((objects, len(COLOURS) + len(SHAPES)), dtype=np.float32)
        self._empty_slots = np.zeros((slots - objects) * OBJECT_SIZE)
        self._tokens = np.zeros(self.vocabulary.max_length, dtype=np.int64)
        self._achieved = np.zeros(objects, dtype=bool)
        self._steps = 0
        self._fell = False
        self._area_low = np.array(OBJECT_AREA.low[:2])
        self._area_high = np.array(OBJECT_AREA.high[:2])
        self._spacing = MIN_SPACING_SIZES * 2 * max(max(s.half_extents[:2]) for s in SIM_SHAPES.values())

    # -- episode ---------------------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        rng = self.np_random
        challenge = self.instructor.draw_challenge(rng)
        scene = sample_scene(
            rng,
            self.settings.mode,
            self.n_objects,
            self._area_low,
            self._area_high,
            self._spacing,
            need_shared=challenge is Kind.AMBIGUITY,
            need_same_shape=challenge is Kind.COMMON_GROUND,
            holdout=self.holdout,
            split=self.split,
        )
        self._scene = scene
        self.task.reset(rng)
        self.objects.clear()
        for obj, (x, y) in zip(scene.objects, scene.positions):
            self.objects.spawn(obj.shape, obj.colour, resting_position(obj.shape, x, y))
        place_arm(self.robot, self.objects, self.settings, rng)
        self._start_positions = np.array(self.objects.states().positions)
        self._heights = np.array([SIM_SHAPES[o.shape].height for o in scene.objects])
        self._properties[:] = 0.0
        for k, obj in enumerate(scene.objects):
            self._properties[k, COLOURS.index(obj.colour)] = 1.0
            self._properties[k, len(COLOURS) + SHAPES.index(obj.shape)] = 1.0
        self.instructor.start(rng, scene, challenge)
        if self.settings.mistake_start > 0.0 and rng.random() < self.settings.mistake_start:
            self._act_on_a_wrong_object(rng)
        self._tokens = self.vocabulary.encode(self.instructor.text)
        self._steps = 0
        self._achieved = self._evaluate()
        self._fell = False
        return self._observation(), self._info()

    def _act_on_a_wrong_object(self, rng: np.random.Generator) -> None:
        """The task done on a random wrong object by the scripted oracle before the first step, unseen by the
        instructor, who then corrects as if the agent had done it. An agent reaches this state only by its
        own mistakes, and in correction episodes the recovery from it (let go, move off, go to the goal
        beside what was just moved) is where corrections are lost; a mistake start shows it in any stage."""
        assert self._scene is not None
        self._do_the_task_on(int(rng.choice([k for k in range(self.n_objects) if k != self._scene.goal_index])))

    def _do_the_task_on(self, wrong: int) -> None:
        assert self._scene is not None
        half_extents = np.array([SIM_SHAPES[obj.shape].half_extents for obj in self._scene.objects])
        memory = OracleMemory()
        for _ in range(MISTAKE_STEPS):
            positions = self.objects.states().positions
            view = ArmView(self.robot.state().ee_position, positions, half_extents, wrong, MAX_STEP)
            self.robot.apply_action(self.task.oracle(view, memory))
            self.world.step()
            if self._evaluate()[wrong]:
                return

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """One step of the arm, or with ``questions`` and a last action number above 0, a question: the arm
        holds its last command for ``question_steps`` steps, and the answer is in the observation returned."""
        if self._scene is None:
            raise RuntimeError("call reset() before step()")
        action = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        if action.shape != self.action_space.shape:
            asks = " and whether to ask (questions)" if self.settings.questions else ""
            raise ValueError(f"expected an action of size {self.action_space.shape[0]}{asks}, got shape {action.shape}")
        asks = bool(self.settings.questions and action[-1] > 0.0 and self.instructor.can_answer)
        if asks:  # answered at once; the exchange then takes its steps, in which a waiting correction may come
            self.instructor.answer(self._steps)
            self._tokens = self.vocabulary.encode(self.instructor.text)
            for _ in range(self.settings.question_steps):
                self._simulate()
        else:
            self.robot.apply_action(action[: self.arm_actions])
            self._simulate()
        success = bool(self._achieved[self._scene.goal_index])
        # Truncated, not terminated: ending there must not look like the zero future value of a success.
        self._fell = not success and bool(self.objects.states().positions[self._scene.goal_index, 2] < FALLEN)
        out_of_time = self.max_episode_steps is not None and self._steps >= self.max_episode_steps
        truncated = not success and (out_of_time or self._fell)
        penalty = self.settings.question_penalty if asks else 0.0
        return self._observation(), reward(success) - penalty, success, truncated, self._info(asked=asks)

    def _simulate(self) -> None:
        """One physics step, judged by the task and then by the instructor, who may speak a correction in
        the observation of this very step."""
        self.world.step()
        self._steps += 1
        self._achieved = self._evaluate()
        if self.instructor.observe(self.np_random, self._steps, self._achieved):
            self._tokens = self.vocabulary.encode(self.instructor.text)

    # -- what the agent and the tools see --------------------------------------------------------------

    def _evaluate(self) -> np.ndarray:
        """Per object, whether the task holds for it."""
        states = self.objects.states()
        contacts = self.robot.contacts(self.objects.body_ids)
        view = TaskView(
            left_finger=contacts.left_finger,
            right_finger=contacts.right_finger,
            positions=states.positions,
            start_positions=self._start_positions,
            heights=self._heights,
            ee_position=self.robot.state().ee_position,
        )
        return self.task.achieved(view)

    def _observation(self) -> dict[str, np.ndarray]:
        robot = self.robot.state()
        states = self.objects.states()
        per_object = np.concatenate(
            [
                states.positions,
                states.positions - robot.ee_position,
                states.positions - self._start_positions,
                states.orientations,
                states.linear_velocities,
                states.angular_velocities,
                self._properties,
            ],
            axis=1,
        )
        observation = np.concatenate(
            [robot.ee_position, robot.ee_velocity, [robot.finger_width], per_object.ravel(), self._empty_slots]
        ).astype(np.float32)
        return {"observation": observation, "instruction": self._tokens.copy()}

    def _info(self, asked: bool = False) -> dict[str, Any]:
        assert self._scene is not None
        spoken = self.instructor.spoken
        return {
            "is_success": bool(self._achieved[self._scene.goal_index]),
            "achieved": self._achieved.copy(),
            "goal_index": self._scene.goal_index,
            "object_positions": np.array(self.objects.states().positions),
            "objects": self._scene.objects,
            "instruction_text": self.instructor.text,
            "challenge": self.instructor.challenge,
            "fell": self._fell,
            "correction": None if spoken is None else spoken.as_info(),
            "asked": asked,
            "answers": [answer.as_info() for answer in self.instructor.answers],
            "referent": self.instructor.referent,
            "fits": self.instructor.fits,
        }

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        from lanrocli.envs.caption import caption

        width, height = IMAGE_SIZE
        return caption(self.world.render(width, height), self.instructor.text)

    def close(self) -> None:
        self.world.close()
