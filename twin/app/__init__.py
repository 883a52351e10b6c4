"""The applications: a mission run from its config, batches of them, the Monte Carlo evaluation.

Configuration and the device factory, the ``Mission`` (the one place where a view happens), the
survey plan, run folders, batches and sweeps with their executors, the Rerun recorder and the
figures. This layer may import everything below it (``twin.core``, ``twin.rfch``, ``twin.sim``
and ``hardware`` lazily, where a config asks for them); nothing below imports it.
"""
