"""The ``robocell`` command: one entry point for every part of robocell (``robocell.main``)."""
