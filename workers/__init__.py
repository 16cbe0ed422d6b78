"""robocell's worker processes."""
