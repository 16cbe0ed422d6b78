"""robocell's shell: command line, scan bundles, simulation and (later) the cell daemon."""
