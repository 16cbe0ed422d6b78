"""robocell: graspable models of unknown objects from a robot cell.

The ``robocell`` command is ``robocell.cli.main``. For programs, the cell's Python API
(``robocell.api``)::

    import robocell

    with robocell.Client("tcp/127.0.0.1:7447", cell="cell1") as cell:
        result = cell.scan([0.6, 0.0, 0.05])

:class:`Client` (blocking), :class:`AsyncClient` (asyncio), the typed results
(:class:`ScanResult`, :class:`JobStatus`, :class:`JobEvent`, :class:`CellStatus`) and the
errors (:class:`JobFailed`, :class:`CellError`) are loaded on first use, so that the command
starts without Zenoh or pydantic.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

__all__ = ["Client", "AsyncClient", "JobFailed", "CellError", "ScanRequest", "ScanResult", "JobStatus",
           "JobEvent", "JobState", "CellStatus"]

if TYPE_CHECKING:
    from .api import (AsyncClient, CellError, CellStatus, Client, JobEvent, JobFailed, JobState, JobStatus,
                      ScanRequest, ScanResult)


def __getattr__(name: str):
    if name in __all__:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'robocell' has no attribute {name!r}")
