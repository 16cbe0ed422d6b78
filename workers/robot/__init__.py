"""The robot worker (``worker``), the interface it drives (``backend.RobotBackend``) and the KUKA
bridges (``kuka``); the simulated robot is ``workers.sim.robot``."""
