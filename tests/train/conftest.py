from __future__ import annotations


import pytest

from .runs import Baseline, finish, tiny, train


@pytest.fixture(scope="session")
def straight(tmp_path_factory: pytest.TempPathFactory) -> Baseline:
    """The tiny curriculum on two environments, trained by ``lanro train`` without interruption: what every
    interrupted or damaged run must end up equal to, and the run folder whose files are checked. Trained
    once for all of them, as it is the slowest thing here; the tests only read it."""
    folder = tmp_path_factory.mktemp("straight")
    path = tiny(folder, envs=2)
    finish(train([str(path), "--out", "straight"], folder))
    return Baseline(path, folder / "straight")
