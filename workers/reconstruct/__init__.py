"""The reconstruction worker (``worker``): a process pool around ``core_cy``, shared by every cell."""
