"""Jobs that belong to their client: the job token.

The answer to a submit carries a secret, the job's token (``JobStatus.token``,
in that answer only). Whoever holds it may cancel the job and decide its pick
(``CancelRequest``, ``PickDecision`` in ``wire/messages.py``); anyone else who
can reach the cell may still read the job, as before. The daemon keeps only
the token's digest (what a stolen copy of the store gives away is no token),
and compares digests in constant time.

A submit repeated with the same ``request_id`` is answered with the same job:
the daemon cannot give the token again (it kept only the digest), so the
repeated answer carries none; the client keeps the token of its first answer
(``AsyncCellClient.submit`` retries with one request, which gets one answer
that counts).

Pure functions; the daemon (cell engineer's code) wires them in: see the
report of issue 23 for where.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets

from robocell.wire.messages import JOB_TOKEN_BYTES

__all__ = ["JobTokenRefused", "new_token", "token_digest", "check_token"]


class JobTokenRefused(ValueError):
    """A cancel or pick decision without the job's token, or with another one."""


def new_token() -> str:
    """A new job token: :data:`~wire.messages.JOB_TOKEN_BYTES` random bytes, URL-safe text."""
    return secrets.token_urlsafe(JOB_TOKEN_BYTES)


def token_digest(token: str) -> str:
    """What the daemon stores of a token: its SHA-256, hex.

    >>> len(token_digest(new_token()))
    64
    """
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def check_token(job_id: str, presented: str | None, digest: str | None) -> None:
    """Pass if ``presented`` is the token whose digest the job keeps.

    A job that keeps no digest (submitted before the daemon issued tokens) takes any
    request, as before.

    Raises
    ------
    JobTokenRefused
        One line naming the job: no token shown, or not the job's.

    >>> token = new_token()
    >>> check_token("7", token, token_digest(token))
    >>> check_token("7", "guessed" * 4, token_digest(token))
    Traceback (most recent call last):
    ...
    robocell.cell.tokens.JobTokenRefused: job 7: the token shown is not the job's: only the client that submitted it may do this
    """
    if digest is None:
        return
    if presented is None:
        raise JobTokenRefused(f"job {job_id}: no token shown: only the client that submitted it may do this "
                              f"(its submit's answer holds the token)")
    if not hmac.compare_digest(token_digest(presented), digest):
        raise JobTokenRefused(f"job {job_id}: the token shown is not the job's: only the client that submitted it "
                              f"may do this")
