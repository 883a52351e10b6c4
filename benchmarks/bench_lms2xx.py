"""Scan rate of the emulated SICK LMS200 through a pseudo-terminal, and the time from a scan's
emission to ``LMS2xx.scan()`` returning it.

    python benchmarks/bench_lms2xx.py [--seconds 10] [--baud 38400]

The emulator streams on a pty at the rate the driver negotiated (from 9600 to ``--baud``), its
ranges from a source that stamps each scan: every beam of scan k reads 1 m + k mm, and the time
the emulator evaluated it is kept, so the driver's side knows which scan ``scan()`` returned and
when it was emitted. Each setting runs for ``--seconds`` of wall time:

* 180 deg at 1 deg (181 values, 372 bytes) and at 0.5 deg (361 values, 732 bytes), every byte
  taking its time on the line (10 bits at the baud rate), as on the robot: the line sets the
  rate (~10 Hz and ~5 Hz at 38400) and the latency (the telegram's 97 / 191 ms on the wire);
* the same at 1 deg with ``line_time=False``: bytes as fast as the pty takes them, so what is
  left is the emulator, the pty and the driver's reader thread.

Printed per setting: scans the driver decoded per second, ``scan()`` returns per second (a
call waits for a scan that began after it, so back-to-back calls get every other scan when a
telegram takes most of the period on the line), and the emission-to-return latency (median,
p95, max).
"""

from __future__ import annotations

import argparse
import statistics
import threading
import time

import numpy as np

from hardware.lms2xx import LMS2xx
from twin.serial_twins.lms2xx import LmsTiming, serve_lms2xx


class StampedSource:
    """Ranges that name their scan: 1 m + k mm on every beam of the k-th scan emitted."""

    def __init__(self) -> None:
        self.emitted: list[float] = []
        self._lock = threading.Lock()

    def __call__(self, angles: np.ndarray) -> np.ndarray:
        with self._lock:
            k = len(self.emitted)
            self.emitted.append(time.monotonic())
        return np.full(len(angles), 1.0 + 0.001 * (k % 5000))

    def emitted_at(self, ranges: np.ndarray) -> float:
        k = round((float(ranges[0]) - 1.0) / 0.001)
        return self.emitted[k]


def run(resolution: float, baud: int, line_time: bool, seconds: float) -> str:
    source = StampedSource()
    timing = LmsTiming(line_time=line_time)
    with (
        serve_lms2xx(source, timing=timing) as server,
        LMS2xx.open(server.path, resolution=resolution, baud=baud) as laser,
    ):
        laser.scan()  # the stream is running
        first, began = laser.scans_received, time.monotonic()
        latencies, returns = [], 0
        while time.monotonic() - began < seconds:
            scan = laser.scan()
            latencies.append(time.monotonic() - source.emitted_at(scan.ranges))
            returns += 1
        elapsed = time.monotonic() - began
        decoded = laser.scans_received - first
    ordered = sorted(latencies)
    p95 = ordered[min(len(ordered) - 1, int(0.95 * len(ordered)))]
    label = f"{resolution:g} deg at {baud} baud" + ("" if line_time else ", no line time")
    return (
        f"{label:34s} decoded {decoded / elapsed:5.1f} scans/s, scan() returned "
        f"{returns / elapsed:5.1f}/s; emission to return: median "
        f"{statistics.median(ordered) * 1e3:6.1f} ms, p95 {p95 * 1e3:6.1f} ms, "
        f"max {ordered[-1] * 1e3:6.1f} ms ({returns} scans)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="wall seconds per setting")
    parser.add_argument("--baud", type=int, default=38400, help="streaming rate (38400)")
    args = parser.parse_args()
    for resolution, line_time in ((1.0, True), (0.5, True), (1.0, False)):
        print(run(resolution, args.baud, line_time, args.seconds), flush=True)


if __name__ == "__main__":
    main()
