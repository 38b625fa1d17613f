"""Shared test setup: one torch thread, as the small networks here run fastest that way on two cores
(and tests of several processes would otherwise oversubscribe them)."""

import pytest
import torch

from tests.train.runs import Baseline, finish, tiny, train

torch.set_num_threads(1)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The files that hold slow tests first, in their own order otherwise. pytest-xdist hands each worker whole
    files in this order as it runs short of work (``--no-loadscope-reorder``): a long file handed out last would
    leave the other workers idle while it runs."""
    slow = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow)


@pytest.fixture(scope="session")
def straight(tmp_path_factory: pytest.TempPathFactory) -> Baseline:
    """The tiny curriculum on two environments, trained by ``lanro train`` without interruption: what every
    interrupted or damaged run must end up equal to, and the run folder whose files are checked. Trained
    once for all of them, as it is the slowest thing here; the tests only read it."""
    folder = tmp_path_factory.mktemp("straight")
    path = tiny(folder, envs=2)
    finish(train([str(path), "--out", "straight"], folder))
    return Baseline(path, folder / "straight")
