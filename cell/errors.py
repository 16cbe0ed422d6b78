"""Errors of robocell's shell: bundles, jobs, workers and transport.

::

    CellError (Exception)
    └── BundleError        a scan bundle is missing, unreadable or invalid

Errors of the reconstruction itself are ``core_cy.errors.CoreError``.
"""

from __future__ import annotations

__all__ = ["CellError", "BundleError"]


class CellError(Exception):
    """Base class of the shell's errors."""


class BundleError(CellError):
    """A scan bundle is missing, unreadable or does not follow DESIGN.md §3."""
