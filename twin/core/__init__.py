"""The core of the method: what every other layer builds on, and which builds on nothing of theirs.

Errors, planar geometry and the camera model, the device contract (what a camera, a pan-tilt
head and a base promise), the accumulator grid with its coverage kernel and fusion rules, and
the project's file formats. It imports numpy (and numba for the kernels) but no device library,
no MuJoCo, no Rerun and nothing else of ``twin``: the hardware drivers (``hardware/``), the twin
(``twin.sim``) and the applications (``twin.app``) all import it; it imports none of them.
"""
