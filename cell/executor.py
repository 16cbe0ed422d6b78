"""A thread that runs the calls given to it, in order: :class:`Serial`.

The job store runs in a thread of its own (an SQLite connection belongs to one
thread); the event loop awaits each call's answer.
"""

from __future__ import annotations

import asyncio
import functools
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

__all__ = ["Serial"]

_T = TypeVar("_T")


class Serial:
    """One thread that runs the calls given to it, in the order they were made."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._executor = ThreadPoolExecutor(1, thread_name_prefix=name)

    def call(self, function: Callable[..., _T], *args: Any, **kwargs: Any) -> asyncio.Future[_T]:
        """Run ``function`` in the thread after every call made before; the future of its result.

        The call is handed over now, not when the future is awaited: a call made after it runs
        after it, even if the caller awaits this one later.
        """
        return asyncio.wrap_future(self._executor.submit(functools.partial(function, *args, **kwargs)))

    def close(self) -> None:
        """Run what was handed over, then end the thread."""
        self._executor.shutdown(wait=True)
