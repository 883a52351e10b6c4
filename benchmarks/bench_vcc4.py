"""Round-trip time of a VC-C4 command through a pseudo-terminal, and of a whole move.

    python benchmarks/bench_vcc4.py [--count 300] [--latency 0.010] [--baud 9600] [--moves 10]

The driver opens the pty like a serial port and sends position requests (``FF 30 30 00 63 EF``,
14-byte answer) to the emulator, which answers after ``--latency`` seconds like the camera (the
manual: 10 ms typical, 30 ms max) plus the answer's time on a ``--baud`` line (14.6 ms at 9600).
With ``--latency 0 --baud 0`` the figure is the pty and the code alone. The same requests are
then timed through the AUX1 tunnel (ARCOS driver and emulator on their own pty). Moves drive
the MuJoCo head (world stepped at 4x wall-clock time): wall seconds for a move of 30 degrees at
top speed, from the command to the driver seeing the head at rest.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

from hardware.arcos import ArcosBase
from hardware.vcc4 import VCC4
from twin.serial_twins.arcos import serve_arcos
from twin.serial_twins.runner import WorldRunner
from twin.serial_twins.vcc4 import SimHeadActuator, VCC4Emulator, VCC4Timing, serve_vcc4
from twin.sim import make_sim_robot


def _quantiles(samples: list[float]) -> tuple[float, float]:
    ordered = sorted(samples)
    return statistics.median(ordered), ordered[min(len(ordered) - 1, int(0.95 * len(ordered)))]


def _time_requests(camera: VCC4, count: int) -> tuple[float, float]:
    for _ in range(10):
        camera.position()  # warm up
    trips = []
    for _ in range(count):
        start = time.perf_counter()
        camera.position()
        trips.append(time.perf_counter() - start)
    return _quantiles(trips)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=300, help="position requests to time")
    parser.add_argument("--latency", type=float, default=0.010, help="emulated answer delay, s")
    parser.add_argument("--baud", type=int, default=9600, help="emulated line speed; 0: instant")
    parser.add_argument("--moves", type=int, default=10, help="30-degree moves to time")
    args = parser.parse_args()

    sim, _ = make_sim_robot()
    timing = VCC4Timing(latency=args.latency, baud=args.baud, power_seconds=0.2, init_seconds=0.2)
    with (
        WorldRunner(sim, time_scale=4.0),
        serve_vcc4(sim, timing=timing) as server,
        VCC4.open(server.path) as camera,
    ):
        median, p95 = _time_requests(camera, args.count)
        print(
            f"position request round trip through the pty ({args.count} requests, emulated "
            f"latency {args.latency * 1e3:.0f} ms, {args.baud} baud): "
            f"median {median * 1e3:.2f} ms, p95 {p95 * 1e3:.2f} ms"
        )
        moves = []
        for k in range(args.moves):
            target = math.radians(30.0 if k % 2 == 0 else 0.0)
            start = time.perf_counter()
            camera.move_to(target)
            moves.append(time.perf_counter() - start)
        median, p95 = _quantiles(moves)
        print(
            f"30-degree move at 90 deg/s, world at 4x ({args.moves} moves): wall median "
            f"{median * 1e3:.0f} ms, p95 {p95 * 1e3:.0f} ms (ideal 83 ms + settling)"
        )
    aux1 = VCC4Emulator(SimHeadActuator(sim), timing=timing)
    with (
        WorldRunner(sim, time_scale=4.0),
        serve_arcos(sim, aux1=aux1) as server,
        ArcosBase.open(server.path) as base,
        VCC4(base.aux_transport(1), answer_timeout=1.0) as camera,
    ):
        count = max(1, args.count // 3)
        median, p95 = _time_requests(camera, count)
        print(
            f"position request round trip through the ARCOS AUX1 tunnel ({count} requests): "
            f"median {median * 1e3:.2f} ms, p95 {p95 * 1e3:.2f} ms"
        )


if __name__ == "__main__":
    main()
