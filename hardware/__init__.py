"""Drivers for the real robot's devices (VC-C4 camera head, ARCOS base, OpenCV camera)."""
