"""The contract every robocell process shares: what crosses the wire, and how.

    messages    the pydantic models of every message, JSON with a ``schema_version``
    keys        the Zenoh key expressions
    errors      the error tree; an error's kind survives the wire (``ErrorReply.kind``)
    transport   an asyncio face for one Zenoh session (queries, queryables, publications, liveliness)
    config      the one configuration file, with each backend's model in a discriminated union
    process     what every process does: open its session, run until SIGINT/SIGTERM
    client      clients of a cell, for asyncio programs and for scripts
    bundle      scan bundles on disk (DESIGN.md §3), untrusted input

This package imports nothing from the daemon (``cell``), the workers or the
simulators (``workers``) or the command line (``robocell``); it may use the pure
core (``core_cy``). A test checks this.
"""
