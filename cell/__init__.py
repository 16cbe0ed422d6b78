"""The cell daemon and what only it uses: jobs as state machines, their steps, the job store,
the reconstruction pool, the Rerun recordings. It speaks to the workers through ``wire``."""
