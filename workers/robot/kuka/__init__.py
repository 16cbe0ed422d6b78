"""The KUKA bridges: KukaVarProxy and OpenOPC-gateway clients, E6POS conversion, and the robot backend.

``backend.KukaBackend`` implements the robot worker's ``RobotBackend`` over
either client (``kvp.KvpClient``, ``opc.OpcClient``); ``backend.make_client``
and ``KukaBackend.from_config`` build them from ``wire.backends.KukaConfig``;
``variables`` names every KRL variable they use; ``errors`` is their exception tree.
Nothing is imported here, so that using KukaVarProxy never imports Pyro5.
"""
