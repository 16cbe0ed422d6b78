"""The daemon's store thread (``cell.executor.Serial``): calls run in the order they were made, in
one thread of their own, and a call's error comes back to its caller."""

from __future__ import annotations

import asyncio
import threading

import pytest

from cell.executor import Serial


def _run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, timeout=10.0))


def test_calls_run_in_the_order_they_were_made_in_one_thread_of_their_own():
    async def main():
        serial, ran = Serial("test"), []
        try:
            first = serial.call(lambda: ran.append(("first", threading.current_thread().name)) or 1)
            second = serial.call(lambda: ran.append(("second", threading.current_thread().name)) or 2)
            assert await second == 2 and await first == 1  # awaited out of order, run in order
        finally:
            serial.close()
        return ran

    ran = _run(main())
    assert [what for what, _ in ran] == ["first", "second"]
    assert {thread for _, thread in ran} == {"test_0"} and "test_0" != threading.current_thread().name


def test_a_failing_call_raises_in_its_caller_and_the_next_call_still_runs():
    async def main():
        serial = Serial("test")
        try:
            with pytest.raises(ZeroDivisionError):
                await serial.call(lambda: 1 / 0)
            return await serial.call(lambda: "still here")
        finally:
            serial.close()

    assert _run(main()) == "still here"


def test_close_runs_what_was_handed_over():
    ran = []

    async def main():
        serial = Serial("test")
        serial.call(ran.append, "handed over before the close")
        serial.close()

    _run(main())
    assert ran == ["handed over before the close"]
