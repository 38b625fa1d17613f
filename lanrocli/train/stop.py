"""How ``lanro train`` and ``lanro sweep`` stop when asked: the first Ctrl-C or SIGTERM is a request to write a
checkpoint and stop, a second Ctrl-C aborts. Kept apart from the displays so that ``lanro sweep``, whose
training happens in Ray's workers, loads neither torch nor pybullet for it."""

from __future__ import annotations

import signal
import sys
from types import FrameType, TracebackType
from typing import Any


class StopRequest:
    """Turns the first Ctrl-C (or SIGTERM, as a cluster sends before it kills a job) into a polite request
    that the run checkpoints and stops; a second Ctrl-C aborts at once."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self._requested = False
        self._previous: dict[int, Any] = {}

    def requested(self) -> bool:
        return self._requested

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self._requested:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            raise KeyboardInterrupt
        self._requested = True
        print("\nstopping: writing a checkpoint (press Ctrl-C again to abort without one)", file=sys.stderr, flush=True)

    def __enter__(self) -> StopRequest:
        for signum in self.SIGNALS:
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
