"""The SAC agent: it learns, it is deterministic given its seed, and its state survives a weights-only load."""

from __future__ import annotations

import dataclasses
import io
import logging

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from lanrocli.agent.buffer.replay_buffer import ReplayBuffer
from lanrocli.agent.buffer.transitions import Batch
from lanrocli.agent.networks import ObjectLayout
from lanrocli.agent.sac import SACAgent
from lanrocli.agent.settings import CRITIC_METRICS, UPDATE_METRICS, BufferSettings, SACSettings
from lanrocli.core.choices import ActingAttention
from tests.agent.episodes import ACTION_DIM, OBS_DIM, VOCAB, random_episode


def observed(agent: SACAgent, raw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Normalised observations and, for an object-wise agent, which slots hold objects, as the agent reads them."""
    return agent.normalizer(raw), None if agent.layout is None else agent.layout.present(raw)


RED = VOCAB.encode("reach the red cube")
BLUE = VOCAB.encode("reach the blue cube")


def _batch(rng: np.random.Generator, size: int = 64) -> Batch:
    """A one-step problem: moving right (action[0] > 0) succeeds for the red cube, left for the blue one."""
    red = rng.random(size) < 0.5
    action = rng.uniform(-1, 1, size=(size, ACTION_DIM)).astype(np.float32)
    success = (action[:, 0] > 0) == red
    instruction = np.where(red[:, None], RED, BLUE)
    return Batch(
        obs=rng.normal(size=(size, OBS_DIM)).astype(np.float32),
        instruction=instruction,
        action=action,
        reward=np.where(success, 0.0, -1.0).astype(np.float32),
        next_obs=rng.normal(size=(size, OBS_DIM)).astype(np.float32),
        next_instruction=instruction.copy(),
        done=np.ones(size, dtype=bool),
        named=np.full(size, -1),
        label=np.full(size, -1),
        slots=np.arange(size),
    )


LAYOUT = ObjectLayout(arm=2, object=3, slots=2)  # OBS_DIM numbers, read as an arm and two objects


def _agent(seed: int = 0, **settings: object) -> SACAgent:
    small = {"hidden_size": 64, "obs_size": 32, **settings}
    return SACAgent(OBS_DIM, ACTION_DIM, len(VOCAB), SACSettings(**small), seed=seed, layout=LAYOUT)  # type: ignore[arg-type]


def _parameters(agent: SACAgent) -> list[torch.Tensor]:
    return [*agent.actor.parameters(), *agent.critic.parameters(), *agent.target_critic.parameters(), agent.log_alpha]


@pytest.mark.parametrize("architecture", ["flat", "objects"])
def test_learns_which_way_each_sentence_asks_for(architecture: str) -> None:
    rng = np.random.default_rng(0)
    agent = _agent(batch_size=128, architecture=architecture)
    for _ in range(250):
        agent.update(_batch(rng, 128))
    obs = rng.normal(size=(100, OBS_DIM)).astype(np.float32)
    right = agent.act({"observation": obs, "instruction": np.tile(RED, (100, 1))}, deterministic=True)
    left = agent.act({"observation": obs, "instruction": np.tile(BLUE, (100, 1))}, deterministic=True)
    assert (right[:, 0] > 0).mean() > 0.95 and (left[:, 0] < 0).mean() > 0.95


def _grounding_batch(rng: np.random.Generator, size: int = 128) -> Batch:
    """Two objects whose first feature is +1 (red) or -1 (blue), in random order; every sentence is a
    relabelled one naming one of them, and ``named`` says which slot."""
    batch = _batch(rng, size)
    red_first = rng.random(size) < 0.5
    objects = batch.obs[:, LAYOUT.arm :].reshape(size, LAYOUT.slots, LAYOUT.object)
    objects[:, 0, 0] = np.where(red_first, 1.0, -1.0)
    objects[:, 1, 0] = -objects[:, 0, 0]
    asks_red = (batch.instruction == RED).all(axis=1)
    batch.named[:] = np.where(asks_red == red_first, 0, 1)
    batch.label = batch.named  # one array: rows left unnamed lose their label too
    return batch


def _attention_on_named(agent: SACAgent, batch: Batch) -> list[float]:
    """Mean attention weight on the named object, for the actor's reader and each critic's."""
    obs, present = observed(agent, torch.as_tensor(batch.obs))
    tokens = torch.as_tensor(batch.instruction)
    named = torch.as_tensor(batch.named)
    weights = []
    with torch.no_grad():
        for network, encoder in ((agent.actor, agent.actor_encoder), (agent.critic, agent.critic.encoder)):
            attention = network.reader.scores(obs, encoder(tokens), present).softmax(dim=-1)
            weights += attention.gather(2, named.expand(attention.shape[0], -1).unsqueeze(2)).mean(dim=(1, 2)).tolist()
    return weights


@pytest.mark.parametrize("architecture", ["flat", "objects"])
def test_act_and_attend_answers_a_batch_as_it_answers_each_row_alone(architecture: str) -> None:
    agent = _agent(architecture=architecture)
    rng = np.random.default_rng(5)
    agent.update_normalizer(rng.normal(size=(50, OBS_DIM)))
    agent.update(_batch(rng))
    obs = {"observation": rng.normal(size=(6, OBS_DIM)).astype(np.float32), "instruction": np.stack([RED, BLUE] * 3)}
    actions, weights = agent.act_and_attend(obs)
    rows = [agent.act_and_attend({key: value[i : i + 1] for key, value in obs.items()}) for i in range(6)]
    np.testing.assert_allclose(actions, np.concatenate([a for a, _ in rows]), atol=1e-6)
    np.testing.assert_allclose(actions, agent.act(obs, deterministic=True), atol=1e-6)
    if architecture == "flat":
        assert weights is None and all(w is None for _, w in rows)
    else:
        assert weights is not None
        np.testing.assert_allclose(weights, np.concatenate([w for _, w in rows]), atol=1e-6)
        np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-6)


def test_argmax_acting_acts_on_the_most_attended_object_alone_and_reports_the_soft_attention() -> None:
    agent = _agent(architecture="objects")
    rng = np.random.default_rng(3)
    agent.update_normalizer(rng.normal(size=(50, OBS_DIM)))
    agent.update(_batch(rng))
    obs = {"observation": rng.normal(size=(6, OBS_DIM)).astype(np.float32), "instruction": np.stack([RED, BLUE] * 3)}
    soft_actions, weights = agent.act_and_attend(obs)
    assert weights is not None and ((weights > 0.05) & (weights < 0.95)).all(), "a split attention, to be decided"
    agent.act_by(ActingAttention.ARGMAX)
    actions, argmax_weights = agent.act_and_attend(obs)
    np.testing.assert_array_equal(argmax_weights, weights)
    assert np.abs(actions - soft_actions).max() > 1e-3
    # The same agent acting softly in the scene without the other object: the attention has one object to weigh.
    alone = obs["observation"].copy().reshape(6, -1)
    objects = alone[:, LAYOUT.arm :].reshape(6, LAYOUT.slots, LAYOUT.object)
    objects[np.arange(6), 1 - weights.argmax(axis=1)] = 0.0
    agent.act_by(ActingAttention.SOFT)
    expected, _ = agent.act_and_attend({"observation": alone, "instruction": obs["instruction"]})
    np.testing.assert_allclose(actions, expected, atol=1e-6)


def test_argmax_acting_needs_object_attention_and_a_known_rule() -> None:
    with pytest.raises(ValueError, match="needs architecture 'objects'"):
        SACSettings(acting_attention="argmax")
    with pytest.raises(ValueError, match="'soft' or 'argmax'"):
        SACSettings(architecture="objects", acting_attention="hard")


def test_grounding_loss_teaches_every_reader_which_object_a_sentence_names() -> None:
    rng = np.random.default_rng(0)
    agent = _agent(critics=2, architecture="objects")
    held_out = _grounding_batch(np.random.default_rng(1), 200)
    before = _attention_on_named(agent, held_out)
    for _ in range(150):
        metrics = agent.update(_grounding_batch(rng))
    after = _attention_on_named(agent, held_out)
    assert len(after) == 3 and all(0.3 < w < 0.7 for w in before) and all(w > 0.95 for w in after)
    assert metrics["grounding_loss"] < 0.2


def test_without_the_sentence_in_the_trunk_it_acts_through_the_attention_alone() -> None:
    """In a scene of one object the attention has one choice, so the sentence can change nothing."""
    agent = _agent(architecture="objects", sentence_in_trunk=False)
    obs = np.random.default_rng(0).normal(size=(2, OBS_DIM)).astype(np.float32)
    obs[:, LAYOUT.arm + LAYOUT.object :] = 0.0  # the second slot is empty
    red = agent.act({"observation": obs, "instruction": np.stack([RED, RED])}, deterministic=True)
    blue = agent.act({"observation": obs, "instruction": np.stack([BLUE, BLUE])}, deterministic=True)
    assert np.array_equal(red, blue)
    with_trunk = _agent(architecture="objects")
    red = with_trunk.act({"observation": obs, "instruction": np.stack([RED, RED])}, deterministic=True)
    assert not np.allclose(
        red, with_trunk.act({"observation": obs, "instruction": np.stack([BLUE, BLUE])}, deterministic=True)
    )
    with pytest.raises(ValueError, match="sentence_in_trunk"):
        SACSettings(architecture="flat", sentence_in_trunk=False)


def test_grounding_loss_is_zero_without_readers_weight_or_relabelled_rows() -> None:
    rng = np.random.default_rng(0)
    assert _agent(architecture="flat").update(_grounding_batch(rng))["grounding_loss"] == 0.0
    assert _agent(architecture="objects", grounding=0.0).update(_grounding_batch(rng))["grounding_loss"] == 0.0
    assert _agent(architecture="objects").update(_batch(rng))["grounding_loss"] == 0.0
    assert _agent(architecture="objects").update(_grounding_batch(rng))["grounding_loss"] > 0.0


@pytest.mark.parametrize(
    ("architecture", "depth", "grounding", "trunk"),
    [
        ("flat", 1, 0.0, True),
        ("objects", 1, 1.0, True),
        ("flat", 0, 0.0, True),
        ("objects", 2, 0.5, True),
        ("objects", 1, 1.0, False),
    ],
)
def test_update_gives_each_network_the_gradient_of_its_own_sac_loss(
    architecture: str, depth: int, grounding: float, trunk: bool
) -> None:
    """The update shares work between the losses (one pass of the encoders, the readers' attention computed
    once for the networks and the grounding loss, the critic's reading of the states reused for the policy's
    action, one backward pass); the gradients must be those of the losses written out one by one."""
    rng = np.random.default_rng(0)
    agent = _agent(
        critics=2, architecture=architecture, hidden_layers=depth, grounding=grounding, sentence_in_trunk=trunk
    )
    agent.update_normalizer(rng.normal(size=(50, OBS_DIM)))
    batch = _grounding_batch(rng)
    batch.named[::3] = -1  # not relabelled: no grounding label
    batch.done[1::2] = False  # these rows' targets read the target critic's values of the next states
    reference = SACAgent.from_state_dict(agent.state_dict())
    agent.optimizer.step = lambda: None  # type: ignore[method-assign,assignment,return-value]  # keep the gradients
    agent.update(batch)

    r = reference
    obs, present = observed(r, torch.as_tensor(batch.obs))
    next_obs, next_present = observed(r, torch.as_tensor(batch.next_obs))
    tokens, next_tokens = torch.as_tensor(batch.instruction), torch.as_tensor(batch.next_instruction)
    alpha = r.log_alpha.exp()
    with torch.no_grad():  # the exploration noise is drawn in the update's order: next actions first
        noise = torch.randn(len(batch.obs), ACTION_DIM, generator=r.generator)
        next_action, next_log_prob = r.actor.sample(next_obs, r.actor.encoder(next_tokens), noise, next_present)
        next_q = r.target_critic(next_obs, r.target_critic.encoder(next_tokens), next_action, next_present)
        not_done = 1.0 - torch.as_tensor(batch.done, dtype=torch.float32)
        soft_value = next_q.min(0).values - alpha * next_log_prob
        target = torch.as_tensor(batch.reward) + r.settings.gamma * not_done * soft_value
        target = target.clamp(-1.0 / (1.0 - r.settings.gamma), 0.0)
    critic_language = r.critic.encoder(tokens)
    q = r.critic(obs, critic_language, torch.as_tensor(batch.action), present)
    critic_loss = (q - target).pow(2).mean(dim=1).sum()
    actor_language = r.actor.encoder(tokens)
    pi_action, log_prob = r.actor.sample(
        obs, actor_language, torch.randn(len(batch.obs), ACTION_DIM, generator=r.generator), present
    )
    q_pi = r.critic(obs, critic_language.detach(), pi_action, present).min(dim=0).values
    actor_loss = (alpha.detach() * log_prob - q_pi).mean()
    alpha_loss = -(r.log_alpha * (log_prob.detach() + r.target_entropy)).mean()
    # Grounding: each reader's attention on the relabelled rows alone, against the object they name.
    rows = torch.as_tensor(np.flatnonzero(batch.named >= 0))
    named = torch.as_tensor(batch.named)[rows]
    critic_grounding = actor_grounding = torch.zeros(())
    if architecture == "objects":
        critic_scores = r.critic.reader.scores(obs[rows], critic_language[rows], present[rows])
        actor_scores = r.actor.reader.scores(obs[rows], actor_language[rows], present[rows])
        critic_grounding = F.cross_entropy(critic_scores.flatten(0, 1), named.repeat(critic_scores.shape[0]))
        actor_grounding = F.cross_entropy(actor_scores[0], named)

    losses = (
        (r.critic, critic_loss + grounding * critic_grounding),
        (r.actor, actor_loss + grounding * actor_grounding),
    )
    for network, loss in losses:
        mine = dict(agent.critic.named_parameters() if network is r.critic else agent.actor.named_parameters())
        expected = torch.autograd.grad(loss, list(network.parameters()), retain_graph=True, allow_unused=True)
        for (name, _), grad in zip(network.named_parameters(), expected):
            got = mine[name].grad
            want = torch.zeros_like(mine[name]) if grad is None else grad
            torch.testing.assert_close(torch.zeros_like(want) if got is None else got, want, rtol=1e-4, atol=1e-6)
    torch.testing.assert_close(agent.log_alpha.grad, torch.autograd.grad(alpha_loss, r.log_alpha)[0])


def test_critic_loss_falls_on_a_fixed_batch() -> None:
    agent = _agent()
    batch = _batch(np.random.default_rng(1), 128)
    first = agent.update(batch)["critic_loss"]
    for _ in range(120):
        last = agent.update(batch)["critic_loss"]
    assert last < 0.2 * first


def test_same_seed_same_batches_same_parameters() -> None:
    a, b, other = _agent(seed=3), _agent(seed=3), _agent(seed=4)
    rng = np.random.default_rng(0)
    for _ in range(5):
        batch = _batch(rng)
        metrics_a, metrics_b = a.update(batch), b.update(batch)
        other.update(batch)
        assert metrics_a == metrics_b
    assert all(torch.equal(x, y) for x, y in zip(_parameters(a), _parameters(b)))
    assert not all(torch.equal(x, y) for x, y in zip(_parameters(a), _parameters(other)))


def test_building_and_training_leave_torch_global_generator_alone() -> None:
    torch.manual_seed(123)
    state = torch.get_rng_state()
    agent = _agent()
    agent.update(_batch(np.random.default_rng(0)))
    agent.act({"observation": np.zeros((2, OBS_DIM), np.float32), "instruction": np.tile(RED, (2, 1))})
    assert torch.equal(torch.get_rng_state(), state)


@pytest.mark.parametrize(
    ("architecture", "compile"),
    [("flat", False), ("objects", False), pytest.param("objects", True, marks=pytest.mark.slow)],
)
def test_state_survives_weights_only_load_and_resumes_bit_identically(
    architecture: str, compile: bool, caplog: pytest.LogCaptureFixture
) -> None:
    rng = np.random.default_rng(0)
    agent = _agent(critics=2, architecture=architecture, compile=compile)
    agent.update_normalizer(rng.normal(size=(50, OBS_DIM)))
    for _ in range(3):
        agent.update(_batch(rng))
    with caplog.at_level(logging.WARNING, logger="lanrocli.agent.noise"):
        resumed = SACAgent.from_state_dict(_round_trip(agent.state_dict()))
    noise_records = [record for record in caplog.records if record.name == "lanrocli.agent.noise"]
    assert not noise_records, "a state saved on this device type continues its noise stream, silently"
    assert resumed.settings == agent.settings and resumed.updates == agent.updates
    obs = {"observation": rng.normal(size=(4, OBS_DIM)).astype(np.float32), "instruction": np.tile(BLUE, (4, 1))}
    for _ in range(3):
        batch = _batch(rng)
        assert agent.update(batch) == resumed.update(batch)
        assert np.array_equal(agent.act(obs), resumed.act(obs))  # same exploration noise too
    assert all(torch.equal(x, y) for x, y in zip(_parameters(agent), _parameters(resumed)))
    assert torch.equal(agent.normalizer.mean, resumed.normalizer.mean)


def _round_trip(state: dict, device: str = "cpu") -> dict:
    """``state`` through a file, read back as a checkpoint is: weights only, onto ``device``."""
    file = io.BytesIO()
    torch.save(state, file)
    file.seek(0)
    return torch.load(file, map_location=device, weights_only=True)


def test_a_state_from_another_device_type_loads_with_a_derived_noise_stream(caplog: pytest.LogCaptureFixture) -> None:
    rng = np.random.default_rng(0)
    agent = _agent(seed=5, architecture="objects")
    agent.update_normalizer(rng.normal(size=(50, OBS_DIM)))
    for _ in range(2):
        agent.update(_batch(rng))
    state = agent.state_dict()
    # What a CUDA generator saves: a seed and an offset, 16 bytes where a CPU generator keeps thousands.
    state["generator"] = torch.tensor([7, *[0] * 7, 32, *[0] * 7], dtype=torch.uint8)
    state["generator_device"] = "cuda"
    with caplog.at_level(logging.WARNING, logger="lanrocli.agent.noise"):
        first, second = (SACAgent.from_state_dict(_round_trip(state)) for _ in range(2))
    assert [r.levelno for r in caplog.records] == [logging.WARNING] * 2
    message = caplog.records[0].getMessage()
    assert "saved on cuda" in message and "seed (5) and update count (2)" in message
    assert first.seed == 5 and first.updates == 2
    assert all(torch.equal(x, y) for x, y in zip(_parameters(agent), _parameters(first)))
    assert not torch.equal(first.generator.get_state(), agent.generator.get_state())
    obs = {"observation": rng.normal(size=(4, OBS_DIM)).astype(np.float32), "instruction": np.tile(RED, (4, 1))}
    assert np.array_equal(agent.act(obs, deterministic=True), first.act(obs, deterministic=True))
    # The new stream is a function of the checkpoint: loading it twice gives the same noise and updates.
    assert np.array_equal(first.act(obs), second.act(obs))
    batch = _batch(rng)
    metrics = first.update(batch)
    assert metrics == second.update(batch) and all(np.isfinite(v) for v in metrics.values())


def test_loading_needs_the_same_architecture_but_keeps_the_learning_settings() -> None:
    state = _agent().state_dict()
    with pytest.raises(ValueError, match="critics"):
        _agent(critics=2).load_state_dict(state)
    with pytest.raises(ValueError, match="laid out"):
        _agent(architecture="objects").load_state_dict(state)
    with pytest.raises(ValueError, match="needs the observation's layout"):
        SACAgent(OBS_DIM, ACTION_DIM, len(VOCAB), SACSettings(architecture="objects"))
    slower = _agent(critic_lr=1e-4, gamma=0.9)
    slower.load_state_dict(state)
    assert slower.settings.gamma == 0.9 and slower.optimizer.param_groups[0]["lr"] == 1e-4


def test_target_critic_follows_by_polyak_averaging() -> None:
    agent = _agent()
    old_target = [p.clone() for p in agent.target_critic.parameters()]
    agent.update(_batch(np.random.default_rng(0)))
    polyak = agent.settings.polyak
    for target, old, online in zip(agent.target_critic.parameters(), old_target, agent.critic.parameters()):
        torch.testing.assert_close(target, polyak * old + (1 - polyak) * online)


def test_actions_lie_in_the_box_batched_or_single() -> None:
    agent = _agent()
    rng = np.random.default_rng(0)
    batch = agent.act({"observation": rng.normal(size=(5, OBS_DIM)) * 100, "instruction": np.tile(RED, (5, 1))})
    single = agent.act({"observation": np.zeros(OBS_DIM), "instruction": RED}, deterministic=True)
    assert batch.shape == (5, ACTION_DIM) and single.shape == (ACTION_DIM,)
    assert np.abs(batch).max() <= 1.0 and np.abs(single).max() <= 1.0


def test_shared_encoder_is_trained_by_the_critic_only() -> None:
    agent = _agent(share_encoder=True)
    assert agent.actor.encoder is None
    encoder_before = [p.clone() for p in agent.critic.encoder.parameters()]
    batch = _batch(np.random.default_rng(0))
    agent.update(batch)
    assert not all(torch.equal(a, b) for a, b in zip(encoder_before, agent.critic.encoder.parameters()))
    assert {id(p) for p in agent.critic.encoder.parameters()}.isdisjoint(id(p) for p in agent.actor.parameters())


def _record_critic_gradients(agent: SACAgent, into: list[list[torch.Tensor]]) -> None:
    """Make each optimiser step of ``agent`` first append the critic's gradients to ``into``."""
    step = agent.optimizer.step

    def recorded(*args: object, **kwargs: object) -> object:
        into.append([torch.zeros_like(p) if p.grad is None else p.grad.clone() for p in agent.critic.parameters()])
        return step(*args, **kwargs)  # type: ignore[arg-type]

    agent.optimizer.step = recorded  # type: ignore[method-assign,assignment]


@pytest.mark.parametrize("share_encoder", [False, True])
def test_an_update_between_the_actors_trains_the_critic_as_a_whole_update_does(share_encoder: bool) -> None:
    """With ``actor_every: 2`` the second update leaves the actor, its encoder and the temperature as they
    were, and gives the critic the gradient a whole update gives it: the losses touch disjoint parameters,
    so leaving the actor's out changes nothing of the critic's."""
    rng = np.random.default_rng(0)
    delayed = _agent(architecture="objects", actor_every=2, share_encoder=share_encoder)
    delayed.update_normalizer(rng.normal(size=(50, OBS_DIM)))
    delayed.update(_grounding_batch(rng))
    assert delayed.updates == 1
    whole = SACAgent.from_state_dict(delayed.state_dict())
    whole.settings = dataclasses.replace(whole.settings, actor_every=1)
    actor_before = [p.clone() for p in delayed.actor.parameters()]
    alpha_before = delayed.log_alpha.detach().clone()
    batch = _grounding_batch(rng)
    critic_grads: list[list[torch.Tensor]] = []
    for agent in (delayed, whole):
        _record_critic_gradients(agent, critic_grads)
        metrics = agent.update(batch)
        assert set(metrics) == set(UPDATE_METRICS if agent is whole else CRITIC_METRICS)
    for got, want in zip(*critic_grads, strict=True):
        torch.testing.assert_close(got, want)
    assert all(torch.equal(a, b) for a, b in zip(actor_before, delayed.actor.parameters()))
    assert torch.equal(delayed.log_alpha.detach(), alpha_before)
    delayed.update(batch)  # the third update trains the actor again
    assert not all(torch.equal(a, b) for a, b in zip(actor_before, delayed.actor.parameters()))


def test_learn_averages_each_metric_over_the_updates_that_report_it() -> None:
    rng = np.random.default_rng(0)
    buffer = ReplayBuffer(2000, OBS_DIM, ACTION_DIM, seed=0)
    for i in range(50):
        buffer.add_episode(random_episode(rng, i))
    agent, twin = _agent(batch_size=32, actor_every=2), _agent(batch_size=32, actor_every=2)
    metrics = agent.learn(buffer, np.random.default_rng(1), n_updates=2)
    sampling = np.random.default_rng(1)
    each = [twin.update(buffer.sample(32, sampling, BufferSettings())) for _ in range(2)]
    assert metrics["actor_loss"] == pytest.approx(each[0]["actor_loss"])
    assert metrics["critic_loss"] == pytest.approx((each[0]["critic_loss"] + each[1]["critic_loss"]) / 2)


def test_learn_samples_relabelled_batches_from_a_buffer() -> None:
    rng = np.random.default_rng(0)
    buffer = ReplayBuffer(2000, OBS_DIM, ACTION_DIM, seed=0)
    for i in range(50):
        buffer.add_episode(random_episode(rng, i))
    agent = _agent(batch_size=32)
    metrics = agent.learn(buffer, rng, n_updates=3)
    assert agent.updates == 3 and set(metrics) >= {"critic_loss", "actor_loss", "alpha", "alpha_loss", "q_mean"}
    assert all(np.isfinite(v) for v in metrics.values())


def test_fixed_temperature_stays_fixed() -> None:
    agent = _agent(autotune_alpha=False, alpha=0.05)
    for _ in range(3):
        metrics = agent.update(_batch(np.random.default_rng(0)))
    assert metrics["alpha"] == pytest.approx(0.05)


def test_settings_reject_nonsense_and_round_trip_as_plain_data() -> None:
    with pytest.raises(ValueError):
        SACSettings(critics=3)
    with pytest.raises(ValueError):
        BufferSettings(relabel_ratio=1.5)
    with pytest.raises(ValueError, match="actor_every"):
        SACSettings(actor_every=0)
    settings = SACSettings(critics=2, max_grad_norm=1.0)
    assert SACSettings.from_dict(dataclasses.asdict(settings)) == settings
    with pytest.raises(ValueError, match="unknown"):
        SACSettings.from_dict({"learning_rate": 1.0})


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_runs_on_cuda_and_matches_the_cpu_initialisation() -> None:
    cpu, cuda = _agent(), SACAgent(OBS_DIM, ACTION_DIM, len(VOCAB), _agent().settings, device="cuda")
    assert all(torch.equal(a, b.cpu()) for a, b in zip(cpu.actor.parameters(), cuda.actor.parameters()))
    metrics = cuda.update(_batch(np.random.default_rng(0)))
    assert np.isfinite(metrics["critic_loss"])
    state = cuda.state_dict()
    assert SACAgent.from_state_dict(state, device="cpu").updates == 1


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_states_move_between_cpu_and_cuda_in_both_directions() -> None:
    rng = np.random.default_rng(0)
    obs = {"observation": rng.normal(size=(4, OBS_DIM)).astype(np.float32), "instruction": np.tile(RED, (4, 1))}
    for source, target in (("cpu", "cuda"), ("cuda", "cpu")):
        agent = SACAgent(OBS_DIM, ACTION_DIM, len(VOCAB), _agent().settings, seed=3, device=source)
        agent.update_normalizer(rng.normal(size=(50, OBS_DIM)))
        agent.update(_batch(rng))
        moved = SACAgent.from_state_dict(_round_trip(agent.state_dict(), target), device=target)
        assert moved.generator.device.type == target
        assert all(t.device.type == target for t in [*_parameters(moved), moved.normalizer.mean])
        # The same weights, but the GPU's kernels sum in another order than the CPU's.
        np.testing.assert_allclose(agent.act(obs, deterministic=True), moved.act(obs, deterministic=True), atol=1e-4)
        assert np.isfinite(moved.update(_batch(rng))["critic_loss"]) and moved.updates == 2
