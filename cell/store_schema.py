"""The job store's SQLite schema (``cell.store``), and what each version adds to the one before."""

from __future__ import annotations

__all__ = ["SCHEMA_VERSION", "SCHEMA", "UPGRADES"]

#: Kept in ``PRAGMA user_version``; a file of an older version is upgraded, a newer one refused.
SCHEMA_VERSION = 4
# What each version adds to the one before it.
UPGRADES = {2: ("ALTER TABLE jobs ADD COLUMN error_kind TEXT",),
             3: ("ALTER TABLE jobs ADD COLUMN progress TEXT", "ALTER TABLE jobs ADD COLUMN checkpoint TEXT",
                 "CREATE TABLE pictures (job_id TEXT NOT NULL REFERENCES jobs (job_id), view INTEGER NOT NULL,"
                 " jpeg BLOB NOT NULL, poses TEXT NOT NULL, PRIMARY KEY (job_id, view))"),
             # Jobs of earlier versions keep none: they take a cancel from anyone, as they did.
             4: ("ALTER TABLE jobs ADD COLUMN token_digest TEXT",)}

# One statement each: sqlite3 runs one at a time inside our transaction (executescript would commit).
SCHEMA = (
    """CREATE TABLE jobs (
        seq INTEGER PRIMARY KEY,                    -- submission order, the counter in job_id
        job_id TEXT NOT NULL UNIQUE,
        request_id TEXT UNIQUE,                     -- NULLs are distinct: only client ids collide
        state TEXT NOT NULL, view INTEGER, n_views INTEGER NOT NULL, error TEXT,
        created REAL NOT NULL, updated REAL NOT NULL, recording TEXT,
        request TEXT NOT NULL,                      -- ScanRequest JSON
        error_kind TEXT,
        progress TEXT,                              -- Progress JSON, while it runs
        checkpoint TEXT,                            -- cell.job.Checkpoint JSON
        token_digest TEXT)                          -- SHA-256 of the job's token (cell.tokens)""",
    "CREATE INDEX jobs_state ON jobs (state)",
    """CREATE TABLE events (seq INTEGER PRIMARY KEY, job_id TEXT NOT NULL REFERENCES jobs (job_id),
        event TEXT NOT NULL)                        -- JobEvent JSON""",
    "CREATE INDEX events_job ON events (job_id)",
    """CREATE TABLE results (job_id TEXT PRIMARY KEY REFERENCES jobs (job_id),
        result TEXT NOT NULL)                       -- ScanResult JSON""",
    """CREATE TABLE pictures (job_id TEXT NOT NULL REFERENCES jobs (job_id), view INTEGER NOT NULL,
        jpeg BLOB NOT NULL, poses TEXT NOT NULL,    -- JSON: where the flange and the camera stood
        PRIMARY KEY (job_id, view))""",
)
