"""What a trained agent does once a correction is spoken: the part of a correction episode that decides it.

Runs a checkpoint's deterministic policy on correction episodes (from the neutral start, like evaluation)
and sorts every episode in which the instructor spoke (``--after 2``: spoke a second time, in a stage with
chains of corrections; everything below then counts from the second) into:

- *succeeded*: the arm then did the task on the goal object;
- *knocked the goal*: it failed, and the goal ended up farther from its start than reach allows (2.5 cm),
  which leaves a reach episode unsolvable; *the goal fell*: it went off the table, the one fall that ends
  an episode (another object lands on the floor and the episode goes on);
- *fell short*: it failed without knocking the goal; the closest the end effector came to the goal object
  after the correction is reported (median), to tell "went elsewhere" from "stopped near".

It says what touched the goal in the few steps before it first moved farther than reach allows: the arm,
another object (one the arm pushed into it), or both; and whether that was before the correction or after.

It also says which object was knocked first (moved more than 2.5 cm), and whether before or after the
correction: in reach, leaving a touched wrong object by dragging it is the typical first slip. In grasp and
lift, where what an object has achieved is its being held (or raised), it also says how many failures held
another object when the correction was spoken (and how many of those still succeeded), and how many failures
still held one at the end: a hand that never lets go of the wrong object cannot take the goal.

And where the arm went next: the first object the task's condition came to hold for after the correction
(the goal; an object it had already acted on, the one corrected or an earlier one; one it had not), or,
where none, whether it stayed on a wrong object to the end. A second correction comes after the arm
misread a first: this tells an arm that goes back to an object already ruled out (it reads the last
correction alone) from one that stays (it reads none) or goes nowhere. For a negation among three objects
it also says whether the object least like the one ruled out is the goal: an arm that reads "not the X" as
"whatever is least like X", a reading that scenes of two objects never contradict, loses where it is not.

    python benchmarks/after_correction.py runs/learning-corrections --episodes 100
    python benchmarks/after_correction.py reach --after 2 --episodes 12000 --negation-rate 0.5 \
        --kinds ambiguity common_ground instruction_correction wrong_object

The episodes use seeds ``--seed`` onwards, the checkpoint's task and object count, and the kinds of
misunderstanding named by ``--kinds`` (default: the two in which the arm must first touch a wrong object);
``--negation-rate 0.5`` makes half the corrections negations, as the correction test does.
"""

from __future__ import annotations

import argparse
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from lanrocli.agent.policy import AgentPolicy
from lanrocli.core.choices import ActingAttention, CorrectionForm
from lanrocli.envs.env import LanroEnv
from lanrocli.language.properties import ObjectProps
from lanrocli.pretrained import agent_path
from lanrocli.tasks.reach import REACH_STILL
from lanrocli.tasks.registry import task_class
from lanrocli.train.testset import CORRECTION_TEST_NEGATION_RATE
from lanrocli.train.trainer import load_policy


@dataclass(frozen=True)
class Outcome:
    """One episode with a spoken correction."""

    result: str  # succeeded, knocked the goal, the goal fell, fell short
    closest: float  # closest approach of the end effector to the goal after the correction, m
    first_knock: str | None  # e.g. "another object, after the correction"; None if nothing moved 2.5 cm
    held_other_at_correction: bool  # another object achieved (held, raised) on the step the correction came
    held_other_at_end: bool  # another object achieved on the last step
    went_next: str  # where the arm went after the correction (``WENT``)
    forms: str  # the forms of the corrections spoken up to it, first to last: "negation, excuse"
    goal_knocked_at_correction: bool  # the goal already more than 2.5 cm from its start when it was spoken
    shortcut: str | None  # a negation among three objects: is the object least like the one ruled out the goal?
    goal_pushed_by: str | None  # what touched the goal in the steps before it first moved 2.5 cm (``PUSHERS``)


def _shortcut(objects: tuple[ObjectProps, ...], goal: int, ruled_out: int) -> str:
    """Whether reading "not the X" as "the object least like X" finds the goal ("agrees"), the third object
    ("disagrees"), or cannot tell ("tie"). A negation means the one object left of those the instruction
    fits; in a scene of two objects the two readings agree, in one of three they need not."""
    (other,) = {0, 1, 2} - {goal, ruled_out}

    def shared(k: int) -> int:
        a, b = objects[k], objects[ruled_out]
        return (a.colour == b.colour) + (a.shape == b.shape)

    return "tie" if shared(goal) == shared(other) else "agrees" if shared(goal) < shared(other) else "disagrees"


PUSHERS = ("the arm", "another object", "the arm and another object", "nothing seen")
"""What touched the goal in the last ``PUSH_STEPS`` steps before it first moved farther than reach allows: the
robot, another object (one the arm pushed into it), both, or neither (contacts are read after each step)."""

PUSH_STEPS = 3
"""Steps looked back from the goal's move: a push builds up over a few steps, and contacts are read only once
per step."""


def _touching_goal(env: LanroEnv, goal: int) -> tuple[bool, bool]:
    """Whether the robot, and whether another object, touches the goal after the last step."""
    bodies = env.objects.body_ids
    robot = bool(env.robot.contacts([bodies[goal]]).robot[0])
    client = env.world.client
    other = any(client.getContactPoints(bodyA=bodies[goal], bodyB=body) for k, body in enumerate(bodies) if k != goal)
    return robot, other


WENT = (
    "the goal",
    "back to the object corrected",
    "back to an object corrected earlier",
    "to another object",
    "stayed on a wrong object",
    "to no object",
)


def _went(goal: int, before: list[int], after: list[int], on_other_at_end: bool) -> str:
    """Where the arm went after the correction: ``before`` and ``after`` are the objects whose condition
    came to hold, in order, up to and from the step the correction was spoken."""
    if after:
        first = after[0]
        if first == goal:
            return WENT[0]
        if before and first == before[-1]:
            return WENT[1]
        return WENT[2] if first in before else WENT[3]
    return WENT[4] if on_other_at_end else WENT[5]


def run(env: LanroEnv, policy: AgentPolicy, seed: int, nth: int = 1) -> Outcome | None:
    obs, info = env.reset(seed=seed)
    start = info["object_positions"]
    goal = info["goal_index"]
    closest = np.inf
    first_knock = None
    held_at_correction = knocked_at_correction = spoken = done = False
    shortcut = None
    achieved = np.zeros_like(info["achieved"])
    reached: tuple[list[int], list[int]] = ([], [])  # objects whose condition came to hold: before, after
    forms: list[str] = []
    touches: list[tuple[bool, bool]] = []
    pushed_by = None
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        done = terminated or truncated
        others_achieved = bool(np.delete(info["achieved"], goal).any())
        positions = info["object_positions"]
        moved = np.linalg.norm(positions - start, axis=1)
        correction = info["correction"]
        if correction is not None and correction["index"] > len(forms):
            forms.append(correction["form"])
        if not spoken and correction is not None and correction["index"] >= nth:
            held_at_correction = others_achieved
            knocked_at_correction = bool(moved[goal] > REACH_STILL)
            wrong = [k for k in reached[0] if k != goal]  # the last of them is the one this correction rules out
            if correction["form"] == CorrectionForm.NEGATION and len(info["objects"]) == 3 and wrong:
                shortcut = _shortcut(info["objects"], goal, wrong[-1])
            spoken = True
        reached[spoken].extend(int(k) for k in np.flatnonzero(info["achieved"] & ~achieved))
        achieved = info["achieved"]
        if spoken:
            closest = min(closest, float(np.linalg.norm(positions[goal] - obs["observation"][:3])))
        touches.append(_touching_goal(env, goal))
        if pushed_by is None and moved[goal] > REACH_STILL:
            robot, other = (any(t[i] for t in touches[-PUSH_STEPS:]) for i in (0, 1))
            pushed_by = PUSHERS[2] if robot and other else PUSHERS[0] if robot else PUSHERS[1] if other else PUSHERS[3]
        if first_knock is None and np.any(moved > REACH_STILL):
            which = "the goal" if int(np.argmax(moved)) == goal else "another object"
            first_knock = f"{which}, {'after' if spoken else 'before'} the correction"
    if not spoken:
        return None
    if info["is_success"]:
        result = "succeeded"
    elif info["fell"]:
        result = "the goal fell"
    elif moved[goal] > REACH_STILL:
        result = "knocked the goal"
    else:
        result = "fell short"
    went = _went(goal, *reached, others_achieved)
    return Outcome(
        result,
        closest,
        first_knock,
        held_at_correction,
        others_achieved,
        went,
        ", ".join(forms[:nth]),
        knocked_at_correction,
        shortcut,
        pushed_by,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkpoint", type=Path, help="checkpoint, pointer file, run folder or shipped agent's name")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--kinds", nargs="+", default=["ambiguity", "instruction_correction"])
    parser.add_argument(
        "--after", type=int, default=1, help="judge from the Nth correction spoken (default: the first)"
    )
    parser.add_argument(
        "--negation-rate",
        type=float,
        help=f"share of corrections spoken as negations, where the agent's stage has them (default: the stage's; "
        f"its correction test: {CORRECTION_TEST_NEGATION_RATE:g})",
    )
    parser.add_argument(
        "--acting-attention", choices=[a.value for a in ActingAttention], help="default: as the agent was trained"
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    settings, policy = load_policy(agent_path(args.checkpoint))
    if args.acting_attention is not None:
        policy.agent.act_by(ActingAttention(args.acting_attention))
    env_settings = settings.env.for_evaluation().replace(correction_rate=1.0, kinds=tuple(args.kinds))
    if args.negation_rate is not None and env_settings.negations:
        env_settings = env_settings.replace(negation_rate=args.negation_rate)
    env = LanroEnv(
        settings.task, env_settings, object_slots=settings.slots, vocabulary=policy.vocabulary, holdout=settings.holdout
    )
    if not 1 <= args.after <= env_settings.max_corrections:
        parser.error(f"--after {args.after}: the agent's stage speaks 1 to {env_settings.max_corrections} corrections")
    outcomes = [run(env, policy, args.seed + i, args.after) for i in range(args.episodes)]
    env.close()
    spoken = [o for o in outcomes if o is not None]
    lost = [str(args.seed + i) for i, o in enumerate(outcomes) if o is not None and o.result != "succeeded"]
    print(f"{args.checkpoint}: {settings.task}, kinds {', '.join(args.kinds)}, seeds {args.seed}..")
    print(f"{args.episodes} episodes, correction {args.after} was spoken in {len(spoken)}")
    results = Counter(o.result for o in spoken)
    for result in ("succeeded", "knocked the goal", "the goal fell", "fell short"):
        near = [o.closest for o in spoken if o.result == result and np.isfinite(o.closest)]
        median = f", closest approach to the goal after it: median {np.median(near) * 100:.1f} cm" if near else ""
        print(f"  {result:<16} {results[result]:>4}{median}")
    knocked = [o for o in spoken if o.goal_knocked_at_correction]
    print(
        f"the goal already knocked (moved more than {REACH_STILL * 100:g} cm) when it was spoken: {len(knocked)}, "
        f"{sum(o.result == 'succeeded' for o in knocked)} succeeded"
    )
    print("where the arm went next (failures of them in brackets):")
    went = Counter(o.went_next for o in spoken)
    went_lost = Counter(o.went_next for o in spoken if o.result != "succeeded")
    for where in WENT:
        print(f"  {where:<36} {went[where]:>4} ({went_lost[where]})")
    print("the corrections' forms, first to last (failures of them in brackets):")
    forms = Counter(o.forms for o in spoken)
    forms_lost = Counter(o.forms for o in spoken if o.result != "succeeded")
    for form, count in forms.most_common():
        print(f"  {form:<36} {count:>4} ({forms_lost[form]})")
    print(
        f"negations as correction {args.after} among three objects, by whether the object least like the one "
        "ruled out is the goal (failures in brackets):"
    )
    for reading in ("agrees", "disagrees", "tie"):
        read = [o for o in spoken if o.shortcut == reading]
        print(f"  {reading:<36} {len(read):>4} ({sum(o.result != 'succeeded' for o in read)})")
    knocks = Counter(o.first_knock for o in spoken if o.result != "succeeded" and o.first_knock is not None)
    print("first object knocked, in the failures:")
    for knock, count in knocks.most_common():
        print(f"  {knock:<36} {count:>4}")
    print(
        f"what touched the goal in the {PUSH_STEPS} steps before it first moved {REACH_STILL * 100:g} cm, in the "
        "failures with the goal knocked (before the correction / after it):"
    )
    moved_goal = [o for o in spoken if o.result != "succeeded" and o.goal_pushed_by is not None]
    for pusher in PUSHERS:
        before = sum(o.goal_pushed_by == pusher and o.goal_knocked_at_correction for o in moved_goal)
        after = sum(o.goal_pushed_by == pusher and not o.goal_knocked_at_correction for o in moved_goal)
        print(f"  {pusher:<36} {before:>4} / {after}")
    if task_class(settings.task).gripper:
        holding = [o for o in spoken if o.held_other_at_correction]
        won = sum(o.result == "succeeded" for o in holding)
        still = sum(o.held_other_at_end for o in spoken if o.result != "succeeded")
        print(f"another object held (or raised) when the correction was spoken: {len(holding)}, {won} succeeded")
        print(f"  failures still holding another object on the last step: {still}")
    print("seeds of the failures, to watch one (lanro eval CHECKPOINT --correction-rate 1 --kinds ambiguity,...")
    print(f"  --episodes 1 --seed S --gif F): {' '.join(lost)}")


if __name__ == "__main__":
    main()
