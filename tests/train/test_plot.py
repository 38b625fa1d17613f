"""Plotting a run folder needs neither torch nor pybullet."""

from __future__ import annotations

import subprocess
import sys


def test_plotting_loads_neither_torch_nor_pybullet() -> None:
    # A fresh interpreter: in this one, other tests have loaded both long ago.
    code = "import lanrocli.train.plot; import sys; print(sorted({'torch', 'pybullet'} & set(sys.modules)))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]", f"importing lanrocli.train.plot loaded {result.stdout.strip()}"
