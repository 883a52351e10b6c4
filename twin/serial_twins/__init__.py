"""Serial twins: emulators that speak the real devices' wire protocols on pseudo-terminals.

They are driven by the MuJoCo world, so the real hardware drivers (``hardware/``) run byte for
byte against the twin: the emulated VC-C4 moves the sim's pan-tilt head, the emulated ARCOS
base drives the sim's wheels and reports its odometry in SIPs. ``WorldRunner`` steps the world
in step with a clock while the drivers talk to the emulators: the wall clock (optionally
faster) on pseudo-terminals, or a test's ``ManualClock`` on lines in memory (``MemoryLink``),
where drivers, emulators and world all run in virtual time.
"""
