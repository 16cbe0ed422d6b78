"""The daemon's store thread (``cell.executor.Serial``): what is handed to it runs in the order it was
handed, deferred work included, on a real thread and a real event loop."""

from __future__ import annotations

import asyncio
import logging
import threading

import pytest

from cell.executor import Serial


def _run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, timeout=10.0))


def test_posts_and_calls_run_in_order_in_one_thread_of_their_own():
    async def main():
        serial, ran = Serial("test"), []
        try:
            serial.post(lambda: ran.append(("post", threading.current_thread().name)))
            answer = serial.call(lambda: ran.append(("call", threading.current_thread().name)) or 42)
            serial.post(ran.append, ("last", "-"))
            assert await answer == 42
            await serial.call(lambda: None)
        finally:
            serial.close()
        return ran

    ran = _run(main())
    assert [what for what, _ in ran] == ["post", "call", "last"]
    assert ran[0][1] == ran[1][1] and ran[0][1].startswith("test")  # the thread's, not the loop's


def test_deferred_work_waits_for_a_flush_or_for_what_comes_after_it():
    async def main():
        serial, ran = Serial("test"), []
        try:
            serial.defer(ran.append, "deferred 1")
            serial.defer(ran.append, "deferred 2")
            await asyncio.sleep(0.05)
            held = list(ran)                       # nothing yet: no flush, nothing after them
            serial.flush()
            await serial.call(lambda: None, ahead=True)
            flushed = list(ran)
            serial.defer(ran.append, "deferred 3")
            await serial.call(ran.append, "a read")  # a call goes after what was deferred before it
            serial.defer(ran.append, "deferred 4")
            serial.post(ran.append, "a write")       # so does a post
            await serial.call(lambda: None)
        finally:
            serial.close()
        return held, flushed, ran

    held, flushed, ran = _run(main())
    assert held == []
    assert flushed == ["deferred 1", "deferred 2"]
    assert ran == ["deferred 1", "deferred 2", "deferred 3", "a read", "deferred 4", "a write"]


def test_a_call_ahead_goes_before_what_is_deferred_and_its_then_after_it_ran():
    async def main():
        serial, ran = Serial("test"), []
        done = asyncio.Event()
        try:
            serial.defer(ran.append, "deferred", then=done.set)
            await serial.call(ran.append, "ahead", ahead=True)
            before = list(ran)
            serial.flush()
            await done.wait()
        finally:
            serial.close()
        return before, ran

    before, ran = _run(main())
    assert before == ["ahead"]
    assert ran == ["ahead", "deferred"]


def test_a_failed_post_is_logged_and_the_thread_goes_on(caplog):
    def broken():
        raise KeyError("no job 'nope'")

    async def main():
        serial = Serial("job-store")
        try:
            serial.post(broken)
            serial.defer(broken)
            return await serial.call(lambda: "still here")
        finally:
            serial.close()

    with caplog.at_level(logging.ERROR):
        assert _run(main()) == "still here"
    failures = [r.getMessage() for r in caplog.records if r.name == "cell.executor"]
    assert failures == ["job-store: KeyError: \"no job 'nope'\""] * 2


def test_a_failed_call_raises_in_the_caller():
    async def main():
        serial = Serial("test")
        try:
            await serial.call(int, "not a number")
        finally:
            serial.close()

    with pytest.raises(ValueError, match="not a number"):
        _run(main())
