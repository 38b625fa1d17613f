"""The squashed-Gaussian actor and the critic ensemble."""

from __future__ import annotations

import numpy as np
import torch

from lanrocli.agent.encoder import LanguageEncoder
from lanrocli.agent.networks import Actor, Critic, EnsembleLinear, ObjectLayout, SceneReader
from lanrocli.language import grammar_vocabulary, sample_sentence

VOCAB = grammar_vocabulary()


def _encoder(seed: int = 0) -> LanguageEncoder:
    torch.manual_seed(seed)
    return LanguageEncoder(len(VOCAB), 32, 32)


def _sentences(n: int, seed: int = 0) -> torch.Tensor:
    rng = np.random.default_rng(seed)
    texts = [sample_sentence(rng, "push", corrections=bool(rng.random() < 0.5), negations=True).text for _ in range(n)]
    return torch.as_tensor(VOCAB.encode_many(texts))


def _actor() -> Actor:
    torch.manual_seed(0)
    return Actor(6, 3, None, 32, 16, 32, 1, -20.0, 2.0)


def test_actor_log_prob_is_the_density_of_the_squashed_gaussian() -> None:
    actor = _actor()
    obs, language = torch.randn(64, 6), torch.randn(64, 32)
    action, log_prob = actor.sample(obs, language, torch.randn(64, 3, generator=torch.Generator().manual_seed(1)))
    mean, log_std = actor(obs, language)
    squashed = torch.distributions.TransformedDistribution(
        torch.distributions.Normal(mean, log_std.exp()), [torch.distributions.TanhTransform()]
    )
    # Keep away from +-1, where float32 atanh loses the precision the reference needs.
    inside = action.abs().amax(dim=1) < 0.999
    expected = squashed.log_prob(action).sum(dim=1)
    torch.testing.assert_close(log_prob[inside], expected[inside], rtol=1e-4, atol=1e-3)
    assert action.abs().max() <= 1.0


def test_deterministic_action_is_the_squashed_mean() -> None:
    actor = _actor()
    obs, language = torch.randn(8, 6), torch.randn(8, 32)
    mean, _ = actor(obs, language)
    assert torch.equal(actor.mode(obs, language), torch.tanh(mean))


def test_log_prob_stays_finite_when_the_action_saturates() -> None:
    actor = _actor()
    with torch.no_grad():
        actor.mean.bias.fill_(30.0)
    _, log_prob = actor.sample(torch.randn(16, 6), torch.randn(16, 32), torch.randn(16, 3))
    assert torch.isfinite(log_prob).all()


def test_ensemble_members_are_independent_linear_layers() -> None:
    torch.manual_seed(0)
    layer = EnsembleLinear(2, 5, 4)
    x = torch.randn(7, 5)
    out = layer(x)
    for i in range(2):
        torch.testing.assert_close(out[i], x @ layer.weight[i] + layer.bias[i])


def test_two_critics_differ_and_each_reads_obs_language_and_action() -> None:
    torch.manual_seed(0)
    critic = Critic(6, 3, _encoder(), 16, 32, 2, n_critics=2)
    obs, language, action = torch.randn(10, 6), torch.randn(10, 32), torch.rand(10, 3)
    q = critic(obs, language, action)
    assert q.shape == (2, 10) and not torch.allclose(q[0], q[1])
    for changed in (
        critic(obs + 1, language, action),
        critic(obs, language + 1, action),
        critic(obs, language, -action),
    ):
        assert not torch.allclose(changed, q)


LAYOUT = ObjectLayout(arm=4, object=5, slots=3)


def _scene(rng: np.random.Generator, batch: int, objects: int) -> torch.Tensor:
    """Raw observations with ``objects`` filled slots, the rest zeros as an environment pads them."""
    obs = torch.zeros(batch, LAYOUT.size)
    obs[:, : LAYOUT.arm + objects * LAYOUT.object] = torch.as_tensor(
        rng.normal(size=(batch, LAYOUT.arm + objects * LAYOUT.object)), dtype=torch.float32
    )
    return obs


def _swap(obs: torch.Tensor, order: list[int]) -> torch.Tensor:
    arm, objects = LAYOUT.split(obs)
    return torch.cat([arm, objects[:, order].reshape(obs.shape[0], -1)], dim=1)


def test_object_wise_networks_ignore_the_order_of_objects_and_the_empty_slots() -> None:
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    encoder = LanguageEncoder(len(VOCAB), 8, 8)
    actor = Actor(LAYOUT.size, 3, encoder, 8, 16, 32, 1, -20.0, 2.0, LAYOUT)
    critic = Critic(LAYOUT.size, 3, encoder, 16, 32, 1, 2, LAYOUT)
    raw = _scene(rng, 6, objects=2)
    language = torch.randn(6, 8)
    action = torch.rand(6, 3) * 2 - 1
    # What normalisation makes of the empty slot is arbitrary: the networks must not read it.
    normalised = raw + 0.5
    present = LAYOUT.present(raw)
    assert present.tolist() == [[True, True, False]] * 6
    mean, _ = actor(normalised, language, present)
    q = critic(normalised, language, action, present)
    for order in ([1, 0, 2], [2, 1, 0], [0, 2, 1]):
        moved = _swap(normalised, order)
        moved_present = LAYOUT.present(_swap(raw, order))
        torch.testing.assert_close(actor(moved, language, moved_present)[0], mean)
        torch.testing.assert_close(critic(moved, language, action, moved_present), q)
    filled = normalised.clone()
    filled[:, -LAYOUT.object :] = 100.0
    torch.testing.assert_close(critic(filled, language, action, present), q)


def test_object_wise_critic_reads_the_objects_the_sentence_and_the_action() -> None:
    torch.manual_seed(1)
    rng = np.random.default_rng(1)
    encoder = LanguageEncoder(len(VOCAB), 8, 8)
    critic = Critic(LAYOUT.size, 3, encoder, 16, 32, 1, 1, LAYOUT)
    raw = _scene(rng, 4, objects=3)
    present = LAYOUT.present(raw)
    language, action = torch.randn(4, 8), torch.rand(4, 3)
    q = critic(raw, language, action, present)
    other_object = raw.clone()
    other_object[:, LAYOUT.arm + 1] += 1.0
    for changed in (
        critic(other_object, language, action, present),
        critic(raw, language + 1.0, action, present),
        critic(raw, language, action - 0.5, present),
    ):
        assert not torch.allclose(changed, q)


def test_scene_reader_returns_the_arm_and_the_object_its_attention_picks() -> None:
    rng = np.random.default_rng(2)
    reader = SceneReader(1, LAYOUT, language_size=8, width=4)
    with torch.no_grad():  # every key is 1000 x the object's first feature, and every query is 1s
        reader.key.weight.zero_()
        reader.key.weight[0, 0, :] = 1000.0
        reader.key.bias.zero_()
        reader.query.weight.zero_()
        reader.query.bias.fill_(1.0)
    raw = _scene(rng, 8, objects=2)  # the third slot empty: its zero feature must never win
    raw[:, LAYOUT.arm :: LAYOUT.object][:, :2] -= 5.0
    present = LAYOUT.present(raw)
    arm, objects = LAYOUT.split(raw)
    out = reader(raw, torch.randn(8, 8), present)[0]
    picked = objects[torch.arange(8), objects[:, :2, 0].argmax(dim=1)]
    torch.testing.assert_close(out, torch.cat([arm, picked], dim=1))
