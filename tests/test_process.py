"""What every robocell process shares: how it ends on an error, and what its command line accepts."""

from __future__ import annotations

import asyncio
import logging

import pytest

from robocell.cli.main import build_parser
from robocell.wire.errors import TransportError
from robocell.wire.process import run_until_stopped


def test_an_expected_error_ends_the_process_with_one_line(caplog):
    async def main(stop: asyncio.Event) -> None:
        raise TransportError("cannot reach the Zenoh router at tcp/127.0.0.1:1")

    with caplog.at_level(logging.INFO):
        assert run_until_stopped(main, "robot worker") == 1
    [record] = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert record.getMessage() == "robot worker stopped: cannot reach the Zenoh router at tcp/127.0.0.1:1"
    assert record.exc_info is None


def test_a_bug_ends_the_process_with_its_traceback(caplog):
    async def main(stop: asyncio.Event) -> None:
        raise KeyError("a bug")

    assert run_until_stopped(main, "robot worker") == 1
    [record] = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert record.exc_info is not None and "robot worker stopped on an error" in record.getMessage()


def test_a_stop_is_a_clean_exit():
    async def main(stop: asyncio.Event) -> None:
        stop.set()
        await stop.wait()

    assert run_until_stopped(main, "robot worker") == 0


def test_a_reconstruction_worker_id_must_fit_in_a_zenoh_key(capsys):
    """A "/" would hide the worker from every daemon; "*", "$", "?" and "#" are Zenoh's own."""
    parser = build_parser()
    for bad in ("lab/gpu1", "gpu*", "a$b", "a?b", "a#b", ".x"):
        with pytest.raises(SystemExit) as info:
            parser.parse_args(["worker", "reconstruct", "--id", bad])
        assert info.value.code == 2
        assert f"argument --id: {bad!r}: use letters, digits" in capsys.readouterr().err
    assert parser.parse_args(["worker", "reconstruct", "--id", "lab-gpu1.r0_2"]).id == "lab-gpu1.r0_2"
