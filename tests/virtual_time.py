"""An asyncio event loop on a clock of its own: time stands still while there is work to do,
and jumps to the next timer when there is none, so a test of timeouts and heartbeats takes no
time and cannot depend on the machine's speed.

Only for code that does all its work on the loop (``wire.fake_transport``): a thread's work
does not hold the clock, which would jump past it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from typing import Any, TypeVar

__all__ = ["VirtualTimeLoop", "run_virtual"]

_T = TypeVar("_T")


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """``loop.time()`` starts at 0 and moves only when nothing is ready to run."""

    def __init__(self) -> None:
        super().__init__()
        self._virtual_now = 0.0

    def time(self) -> float:
        return self._virtual_now

    def _run_once(self) -> None:
        ready = self._ready  # type: ignore[attr-defined]
        scheduled = [h for h in self._scheduled if not h.cancelled()]  # type: ignore[attr-defined]
        if not ready and scheduled:
            self._virtual_now = max(self._virtual_now, min(h.when() for h in scheduled))
        super()._run_once()  # type: ignore[misc]


def run_virtual(coroutine: Coroutine[Any, Any, _T], *, limit_s: float = 600.0) -> _T:
    """Run ``coroutine`` on a :class:`VirtualTimeLoop`; it fails after ``limit_s`` of its time."""
    with asyncio.Runner(loop_factory=VirtualTimeLoop) as runner:
        return runner.run(asyncio.wait_for(coroutine, limit_s))
