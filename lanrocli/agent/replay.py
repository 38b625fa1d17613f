"""An update's operations recorded once and replayed from C++ (``replay.cpp``), with the same numbers.

At batch 64 an update's reading of its sentences, its losses and their backward pass are a few hundred small
tensor operations, and on CPU each costs more to reach, from Python and through autograd, than to compute.
``make_fx`` records the ATen operations one call of a function of tensors runs, the backward pass included
where the function asks autograd for gradients; replaying that list from C++ runs the same kernels on the
same arguments in the same order, so it gives the same numbers bit for bit (``tests/agent/test_replay.py``
holds updates to that), without the interpreter and autograd between the calls.

A recording stands for the function only as long as nothing the function decided in Python changes: the
shapes and types of its inputs, and the Python values it read (the agent's settings, whether a batch has
labels and words), which is what :class:`ReplayedGradients` keys its recordings by. The function must reach
every tensor through its inputs: one it found elsewhere would be recorded as the value it had then, so
:class:`Recording` refuses a function that reads any. Its Python runs once, while recording: a print prints
once, and a branch on a tensor's value cannot be recorded at all (the recording fails and says so).
:attr:`SACSettings.replay <lanrocli.agent.settings.SACSettings.replay>` turns the replay off for changing
:func:`~lanrocli.agent.losses.sac_losses`.
"""

from __future__ import annotations

import copy
import operator
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import torch
from torch.fx import Graph, Node
from torch.fx.experimental.proxy_tensor import make_fx

from lanrocli.agent.acting import Acting
from lanrocli.agent.encoder import LanguageEncoder, encode, native_reading
from lanrocli.agent.losses import Learner, SampledTensors, sac_losses, update_tensors
from lanrocli.agent.native import REPLAY, load
from lanrocli.language import PAD_ID

TIMED_RUNS = 4  # runs of a recording timed one call at a time, the fastest of each call's times kept
ACTING_RECORDED_AFTER = 200  # calls of one kind and shape from Python before acting records it (ReplayedActing)


class Recording:
    """A function of tensors (one argument each), returning a list of tensors, as the operations one call of
    it ran."""

    def __init__(
        self, function: Callable[..., Sequence[torch.Tensor]], inputs: Sequence[torch.Tensor], native: Any, threads: int = 1
    ) -> None:
        graph = make_fx(function)(*inputs).graph
        graph.eliminate_dead_code()
        constants = [node.target for node in graph.nodes if node.op == "get_attr"]
        if constants:
            raise ValueError(f"the recorded function read tensors that are not its inputs ({', '.join(map(str, constants))}); pass them in")
        self._program, calls = _program(graph, native)
        if threads > 1:
            # Ordered on what each call took here, the fastest of a few runs (the first warms the kernels), unless
            # the calls change their inputs, which running them again would change.
            times = [self._program.timed(list(inputs))[1] for _ in range(0 if calls.changes_inputs() else TIMED_RUNS)]
            calls.costs = [min(took) / 1000 for took in zip(*times)] if times else [1.0] * len(calls.reads)
            self._program.schedule(threads, *calls.order())

    def __call__(self, inputs: Sequence[torch.Tensor]) -> list[torch.Tensor]:
        return self._program.run(list(inputs))


def _program(graph: Graph, native: Any) -> tuple[Any, _Calls]:
    """``graph``'s calls as the native ``Program`` replays them: every value a numbered slot, each call the
    operator, its arguments (slots, lists of slots, constants) in its schema's order, the slots its results go
    to, and the slots no later call reads, which it frees."""
    slots: dict[Node, int] = {}
    aliases: dict[Node, Node] = {}  # detach: replayed without autograd, the tensor itself

    def slot(node: Node) -> int:
        while node in aliases:
            node = aliases[node]
        return slots[node]

    def keep(node: Node) -> int:
        slots[node] = len(slots)
        return slots[node]

    def argument(value: Any) -> tuple[str, Any]:
        if isinstance(value, Node):
            return ("value", slot(value))
        if isinstance(value, (list, tuple)) and any(isinstance(v, Node) for v in value):
            return ("values", [-1 if v is None else slot(v) for v in value])  # None: an optional tensor left out
        return ("constant", value)

    inputs = [keep(node) for node in graph.nodes if node.op == "placeholder"]
    calls = []
    drawn: list[bool] = []  # the calls that draw random numbers
    for node in graph.nodes:
        if node.op != "call_function" or node.target is operator.getitem:
            continue
        if node.target is torch.ops.aten.detach.default:
            aliases[node] = node.args[0]
            continue
        schema = node.target._schema
        returns = [str(r.type) for r in schema.returns]
        unpack = returns == ["List[Tensor]"]
        if len(returns) > 1 or unpack:  # getitem nodes take the values out; those none takes are dropped (-1)
            taken = {user.args[1]: user for user in node.users if user.target is operator.getitem}
            count = max(taken, default=-1) + 1 if unpack else len(returns)
            results = [keep(taken[k]) if k in taken else -1 for k in range(count)]
        else:
            results = [keep(node)] if returns else []
        given = [node.args[i] if i < len(node.args) else node.kwargs.get(a.name, a.default_value) for i, a in enumerate(schema.arguments)]
        calls.append((schema, [argument(value) for value in given], results, unpack))
        drawn.append(torch.Tag.nondeterministic_seeded in node.target.tags)
    (output,) = [node for node in graph.nodes if node.op == "output"]
    outputs = [slot(node) for node in output.args[0]]
    if len(set(outputs)) < len(outputs):  # the replay would hand out one tensor twice, where Python gives two
        raise ValueError("the recorded function returns one tensor in two places; return each once")

    reads = [[read for kind, value in arguments for read in _slots(kind, value)] for _, arguments, _, _ in calls]
    last_read = {read: index for index, read_by in enumerate(reads) for read in read_by}
    freed: dict[int, list[int]] = {}
    for read, index in last_read.items():
        if read not in outputs and read not in inputs:
            freed.setdefault(index, []).append(read)
    program = native.Program(len(slots), inputs, outputs)
    for index, (schema, arguments, results, unpack) in enumerate(calls):
        program.add(schema.name, schema.overload_name, arguments, results, unpack, freed.get(index, []))
    return program, _Calls(reads, [results for *_, results, _ in calls], [_aliasing(schema) for schema, *_ in calls],
                           [_written(schema, arguments) for schema, arguments, _, _ in calls], drawn)


def _slots(kind: str, value: Any) -> list[int]:
    """The slots an argument reads (none for a constant, and none for an optional tensor left out)."""
    return [value] if kind == "value" else [slot for slot in value if slot >= 0] if kind == "values" else []


def _aliasing(schema: Any) -> bool:
    """Whether a call's results may share memory with its arguments (a view): its schema says so, or it is
    ``_unsafe_view``, a view whose schema does not."""
    return schema.name == "aten::_unsafe_view" or any(a.alias_info is not None for a in schema.arguments)


def _written(schema: Any, arguments: list[tuple[str, Any]]) -> list[int]:
    """The slots of a call's arguments it changes in place."""
    return [slot for declared, (kind, value) in zip(schema.arguments, arguments)
            if declared.alias_info is not None and declared.alias_info.is_write for slot in _slots(kind, value)]


@dataclass
class _Calls:
    """What a schedule of a program's calls (in recorded order) is planned on."""

    reads: list[list[int]]  # the slots each call reads
    results: list[list[int]]  # the slots it writes (-1: a result nothing reads)
    aliasing: list[bool]  # whether its results may share memory with its arguments
    written: list[list[int]]  # the slots of its arguments it changes in place
    drawn: list[bool]  # whether it draws random numbers
    costs: list[float] = field(default_factory=list)  # microseconds each took, one after another

    def changes_inputs(self) -> bool:
        """Whether a call changes in place a slot no call made: an input."""
        made = {slot for results in self.results for slot in results}
        return any(slot not in made for written in self.written for slot in written)

    def after(self) -> list[set[int]]:
        """The calls each call must follow: those that made what it reads; and all calls before it, where it
        draws random numbers or changes a tensor in place, which all calls after it then follow. A change in
        place follows only the call that made its tensor where that tensor is a fresh result (not a view, not
        an input) which no other call reads: nothing else can see it."""
        made_by = {slot: index for index, results in enumerate(self.results) for slot in results if slot >= 0}
        readers: dict[int, list[int]] = {}
        for index, reads in enumerate(self.reads):
            for slot in reads:
                readers.setdefault(slot, []).append(index)
        after = [{made_by[slot] for slot in reads if slot in made_by} for reads in self.reads]
        barrier: int | None = None
        for index, written in enumerate(self.written):
            unseen = all(slot in made_by and not self.aliasing[made_by[slot]] and readers[slot] == [index] for slot in written)
            if self.drawn[index] or not unseen:
                after[index] |= set(range(index))
                barrier = index
            elif barrier is not None:
                after[index].add(barrier)
        return after

    def order(self) -> tuple[list[int], list[list[int]]]:
        """The order in which threads take the calls, longest remaining path first (the cost of the costliest
        chain of calls from it to the end), which follows every dependency; and what each call follows."""
        after = self.after()
        costs = [max(cost, 1e-3) for cost in self.costs]  # a path strictly longer than any that follows it
        remaining = list(costs)
        for index in reversed(range(len(costs))):
            for before in after[index]:
                remaining[before] = max(remaining[before], costs[before] + remaining[index])
        return sorted(range(len(costs)), key=lambda index: (-remaining[index], index)), [sorted(a) for a in after]


class _AgentReplay:
    """Recordings of functions of one agent's tensors (``_state``, taken once: the optimiser, the observations'
    statistics and ``load_state_dict`` change them in place, as they must for a replay to see it)."""

    _state: list[torch.Tensor]
    _of_the_agent: tuple[str, ...] = ("_agent", "_state")  # attributes that are the agent's, or hold its tensors
    _its_own: tuple[str, ...] = ("_recordings",)  # dictionaries a copy starts empty

    def __deepcopy__(self, memo: dict[int, Any]) -> _AgentReplay:
        """A copy of the agent gets a replay of its own, which records anew: a recording holds the tensors of
        the agent it was made for. What is the agent's is the copy's, through the memo (it may not be whole yet:
        no attribute of it is read here); the rest is shared."""
        copied = type(self).__new__(type(self))
        for name, value in vars(self).items():
            setattr(copied, name, {} if name in self._its_own else copy.deepcopy(value, memo) if name in self._of_the_agent else value)
        return copied


class ReplayedGradients(_AgentReplay):
    """An agent's update up to its optimiser's step, recorded on the first batch of each kind and replayed
    after: the batch's tensors as the losses read them (:func:`~lanrocli.agent.losses.update_tensors`), the
    encoders' reading of its sentences (:func:`~lanrocli.agent.encoder.encode`),
    :func:`~lanrocli.agent.losses.sac_losses`, and the gradients of the losses' sum for the ``learned`` tensors."""

    _of_the_agent = ("_agent", "_state", "_learned", "_encoders")

    def __init__(
        self, native: Any, agent: Learner, learned: Sequence[torch.Tensor], encoders: Sequence[LanguageEncoder], threads: int = 1
    ) -> None:
        self._native, self._threads = native, threads
        self._agent, self._learned, self._encoders = agent, list(learned), list(encoders)
        # Everything the update reads of the agent: its networks (encoders included), the temperature and the
        # observations' statistics.
        self._state = [
            *agent.critic.parameters(), *agent.actor.parameters(), *agent.target_critic.parameters(), agent.log_alpha,
            agent.normalizer.shift, agent.normalizer.scale,
        ]
        self._recordings: dict[tuple[Any, ...], tuple[Recording, list[bool]]] = {}

    def __call__(self, tokens: torch.Tensor, sampled: SampledTensors, labelled: bool) -> tuple[list[torch.Tensor | None], torch.Tensor]:
        """The gradients for each of ``learned`` (None where it has none), and the update's metrics, of the
        batch ``sampled`` whose sentences and next sentences are ``tokens`` (int64 [2B, L])."""
        # A batch without a word reads as zeros, from which nothing learns: a reading of its own.
        worded = bool(tokens.ne(PAD_ID).any())
        # All the settings, though acting's (act_by) never reach the losses: a recording more is cheap.
        key = (self._agent.settings, labelled, worded, tokens.shape, *((t.shape, t.dtype) for t in sampled))
        if key not in self._recordings:
            self._recordings[key] = self._record(tokens, sampled, labelled)
        recording, has_gradient = self._recordings[key]
        *gradients, metrics = recording([*self._state, tokens, *sampled])
        given = iter(gradients)
        return [next(given) if has else None for has in has_gradient], metrics

    def _record(self, tokens: torch.Tensor, sampled: SampledTensors, labelled: bool) -> tuple[Recording, list[bool]]:
        has_gradient: list[bool] = []

        def gradients(*inputs: torch.Tensor) -> list[torch.Tensor]:
            tokens, batch = inputs[len(self._state)], update_tensors(self._agent, SampledTensors(*inputs[len(self._state) + 1 :]))
            summaries = encode(self._encoders, tokens)
            loss, metrics = sac_losses(self._agent, summaries, batch, labelled)
            grads = torch.autograd.grad(loss, self._learned, allow_unused=True)
            has_gradient[:] = [grad is not None for grad in grads]
            return [*(grad for grad in grads if grad is not None), metrics]

        return _recorded("update", gradients, [*self._state, tokens, *sampled], self._native, self._threads), has_gradient


class ReplayedActing(_AgentReplay):
    """An agent's acting (:mod:`lanrocli.agent.acting`), run from Python until one kind and shape of call has been
    made ``after`` times, then recorded and replayed: shapes come and go with the sentences' lengths, and a
    recording costs what a few hundred calls from Python do, so only those that recur are recorded. Acting on
    CPU only, like the update, and the C++ built or loaded at the first recording."""

    _its_own = ("_recordings", "_calls")

    def __init__(self, agent: Acting, after: int = ACTING_RECORDED_AFTER) -> None:
        self._agent, self._after, self._native = agent, after, None
        self._state = list(dict.fromkeys([
            *agent.actor.parameters(), *agent.actor_encoder.parameters(), agent.normalizer.shift, agent.normalizer.scale,
        ]))
        self._calls: dict[tuple[Any, ...], int] = {}
        self._recordings: dict[tuple[Any, ...], Recording] = {}

    def __call__(self, function: Callable[..., list[torch.Tensor]], inputs: list[torch.Tensor]) -> list[torch.Tensor]:
        """``function(agent, *inputs)``, replayed where recorded."""
        key = (function, self._agent.settings, *((t.shape, t.dtype) for t in inputs))
        recording = self._recordings.get(key)
        if recording is None:
            self._calls[key] = calls = self._calls.get(key, 0) + 1
            if calls < self._after or self._load() is None:
                return function(self._agent, *inputs)
            state = len(self._state)
            recording = self._recordings[key] = _recorded(
                f"acting ({function.__name__})", lambda *given: function(self._agent, *given[state:]), [*self._state, *inputs], self._native)
        return recording([*self._state, *inputs])

    def _load(self) -> Any:
        if self._native is None:
            self._native = load(REPLAY) or False  # False: it cannot be built here (warned once)
        return self._native or None


def _recorded(
    what: str, function: Callable[..., Sequence[torch.Tensor]], inputs: Sequence[torch.Tensor], native: Any, threads: int = 1
) -> Recording:
    """A recording of the agent's ``what``, or an error that says what it needs and how to do without."""
    try:
        return Recording(function, inputs, native, threads)
    except RuntimeError as error:  # a branch on a tensor's value, most likely: Python that needs the values
        raise RuntimeError(
            f"the agent's {what} could not be recorded for its replay ({error}); the "
            "networks, sac_losses and acting (lanrocli/agent/acting.py) must be functions of tensors without branches on "
            "their values, or set agent.replay: false to run them from Python"
        ) from error


def update_threads(workers: int) -> int:
    """How many threads a training's replayed update runs on: two where torch's inter-op threads (by default
    the machine's cores; a sweep's trial sets one) leave a core for a helper beside the training's own thread
    and its ``workers`` environment processes, else one. Without that core the helper takes the simulation's
    and the training is no faster (docs/performance.md)."""
    return 2 if torch.get_num_interop_threads() >= workers + 2 else 1


def replayed_gradients(
    agent: Learner, learned: Sequence[torch.Tensor], encoders: Sequence[LanguageEncoder], device: torch.device, threads: int = 1
) -> ReplayedGradients | None:
    """The replay of ``agent``'s update on ``device``, on ``threads`` threads, or None where there is none: on CUDA
    (recorded and checked on CPU only), or on a machine that cannot build ``replay.cpp`` or the C++ reading
    (whose one call a recording holds where the Python reading's steps depend on the batch), each warned once."""
    if native_reading(device) is None:
        return None
    native = load(REPLAY)
    return None if native is None else ReplayedGradients(native, agent, learned, encoders, threads)
