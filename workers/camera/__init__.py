"""The camera worker (``worker``), the interface it drives (``backend.Camera``) and the Axis
camera (``axis``); the simulated cameras are in ``workers.sim``."""
