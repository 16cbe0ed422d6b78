"""The ``robocell`` command: one module per group of subcommands (``main`` lists them)."""
