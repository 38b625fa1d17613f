import copy

import torch

from lanrocli.agent.adam import adam_step


def _twins() -> tuple[torch.optim.Adam, torch.optim.Adam, list[torch.Tensor], list[torch.Tensor]]:
    torch.manual_seed(0)
    params = [torch.nn.Parameter(torch.randn(5, 3)), torch.nn.Parameter(torch.randn(7)), torch.nn.Parameter(torch.randn(()))]
    other = [torch.nn.Parameter(p.detach().clone()) for p in params]

    def adam(ps: list[torch.Tensor]) -> torch.optim.Adam:
        return torch.optim.Adam([{"params": ps[:2], "lr": 3e-4}, {"params": ps[2:], "lr": 1e-2}], fused=True)

    return adam(params), adam(other), params, other


def _gradients(params: list[torch.Tensor], seed: int, skip: int | None = None) -> None:
    generator = torch.Generator().manual_seed(seed)
    for i, p in enumerate(params):
        p.grad = None if i == skip else torch.randn(p.shape, generator=generator)


def test_adam_step_takes_torchs_step_bit_for_bit() -> None:
    ours, torchs, params, other = _twins()
    for step in range(6):
        skip = 1 if step == 3 else None  # a parameter without a gradient is left alone, as torch leaves it
        _gradients(params, step, skip)
        _gradients(other, step, skip)
        adam_step(ours)
        torchs.step()
        for a, b in zip(params, other):
            assert torch.equal(a, b)
    assert all(torch.equal(ours.state[a]["exp_avg_sq"], torchs.state[b]["exp_avg_sq"]) for a, b in zip(params, other))
    assert float(ours.state[params[0]]["step"]) == 6.0 and float(ours.state[params[1]]["step"]) == 5.0


def test_adam_step_continues_a_loaded_state() -> None:
    ours, torchs, params, other = _twins()
    _gradients(other, 0)
    torchs.step()
    for a, b in zip(params, other):
        a.data.copy_(b.data)
    ours.load_state_dict(copy.deepcopy(torchs.state_dict()))
    _gradients(params, 1)
    _gradients(other, 1)
    adam_step(ours)
    torchs.step()
    assert all(torch.equal(a, b) for a, b in zip(params, other))
