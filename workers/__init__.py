"""robocell's worker processes, each behind an interface, and the simulators of the hardware.

    robot        the robot worker; ``RobotBackend`` and its backends (KUKA over KukaVarProxy or OPC)
    camera       the camera worker; ``Camera`` and its backends (an Axis camera over VAPIX)
    reconstruct  the reconstruction worker, a process pool around ``core_cy``
    sim          every simulator: the robot, the KUKA controller, the Axis camera, the scene
"""
