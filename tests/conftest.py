"""Shared test setup: one torch thread, as the small networks here run fastest that way on two cores
(and tests of several processes would otherwise oversubscribe them)."""

import torch

torch.set_num_threads(1)
