import copy
import io

import torch

from lanrocli.agent.adam import AdamStep


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


def _same(ours: torch.optim.Adam, torchs: torch.optim.Adam, params: list[torch.Tensor], other: list[torch.Tensor]) -> bool:
    return all(
        torch.equal(a, b) and all(torch.equal(ours.state[a][k], torchs.state[b][k]) for k in ("exp_avg", "exp_avg_sq", "step"))
        for a, b in zip(params, other)
    )


def test_adam_step_takes_torchs_step_bit_for_bit() -> None:
    ours, torchs, params, other = _twins()
    step = AdamStep(ours)
    for index in range(8):
        skip = 1 if index in (3, 4) else None  # a parameter without a gradient is left alone, as torch leaves it
        _gradients(params, index, skip)
        _gradients(other, index, skip)
        step()
        torchs.step()
        assert _same(ours, torchs, params, other)
    assert float(ours.state[params[0]]["step"]) == 8.0 and float(ours.state[params[1]]["step"]) == 6.0


def test_adam_step_continues_a_loaded_state() -> None:
    ours, torchs, params, other = _twins()
    step = AdamStep(ours)
    _gradients(params, 0)
    step()  # the lists it keeps are of this state, which loading replaces
    _gradients(other, 0)
    torchs.step()
    _gradients(other, 1)
    torchs.step()
    for a, b in zip(params, other):
        a.data.copy_(b.data)
    ours.load_state_dict(copy.deepcopy(torchs.state_dict()))
    for index in (2, 3):
        _gradients(params, index)
        _gradients(other, index)
        step()
        torchs.step()
        assert _same(ours, torchs, params, other)


def test_a_saved_and_loaded_state_steps_on_alike() -> None:
    """The step counters are views of one tensor per group: saved, loaded and stepped again, they count on."""
    ours, torchs, params, other = _twins()
    step = AdamStep(ours)
    for index in range(3):
        _gradients(params, index)
        step()
    file = io.BytesIO()
    torch.save(ours.state_dict(), file)
    file.seek(0)
    for a, b in zip(params, other):
        b.data.copy_(a.data)
    torchs.load_state_dict(torch.load(file, weights_only=True))
    again = AdamStep(torchs)
    for index in (3, 4):
        _gradients(params, index)
        _gradients(other, index)
        step()
        again()
        assert _same(ours, torchs, params, other)
    assert float(torchs.state[other[0]]["step"]) == 5.0


def test_a_copy_steps_apart_from_its_original() -> None:
    ours, _, params, _ = _twins()
    step = AdamStep(ours)
    _gradients(params, 0)
    step()
    copied = copy.deepcopy(step)
    copied_params = [p for group in copied.optimizer.param_groups for p in group["params"]]
    _gradients(copied_params, 1)
    copied()
    assert float(ours.state[params[0]]["step"]) == 1.0
    assert float(copied.optimizer.state[copied_params[0]]["step"]) == 2.0
    assert not torch.equal(params[0], copied_params[0])
