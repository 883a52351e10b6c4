"""ARCOS through a pseudo-terminal: the SIP rate the driver receives and command round trips.

    python benchmarks/bench_arcos.py [--seconds 10] [--trips 50] [--time-scale 1]

The real driver (``hardware.arcos.ArcosBase``) talks to the emulated firmware on a pty while
the emulator drives the MuJoCo robot (world stepped in wall-clock time x ``--time-scale``), and
the robot drives a slow circle so SIPs carry changing odometry. Measured:

* SIP rate: SIPs/s the driver decoded over ``--seconds`` (the firmware sends one per 100 ms).
* AUX round trip: 6 bytes out in a TTY2 packet to an echo device on AUX1, back through GETAUX
  and a SERAUX packet: what every VC-C4 command pays when the camera hangs off the robot.
* Command to SIP: VEL sent until the first SIP showing the robot moving (ARCOS does not
  acknowledge commands, so the SIP stream is the answer; includes up to one 100 ms SIP cycle).
* Virtual time: the same driver, emulator and world on a ``ManualClock`` over a ``MemoryLink``
  (how the tests run them): wall seconds for ``--virtual-seconds`` of driving, i.e. how much
  faster than real time a test of the base runs.

Figures depend on the CPU and on what else runs on it.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

from hardware.arcos import ArcosBase
from hardware.arcos_codec import Command
from twin.core.clock import ManualClock
from twin.serial_twins.arcos import serve_arcos
from twin.serial_twins.bytedevice import EchoDevice
from twin.serial_twins.memory import MemoryLink
from twin.serial_twins.runner import WorldRunner
from twin.sim import make_sim_robot


def _ms(values: list[float]) -> str:
    values = sorted(values)
    p95 = values[min(len(values) - 1, int(0.95 * len(values)))]
    return (
        f"median {1000 * statistics.median(values):.1f} ms, p95 {1000 * p95:.1f} ms, "
        f"max {1000 * values[-1]:.1f} ms (n={len(values)})"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--trips", type=int, default=50)
    parser.add_argument("--time-scale", type=float, default=1.0)
    parser.add_argument("--virtual-seconds", type=float, default=20.0)
    args = parser.parse_args()

    sim, _ = make_sim_robot("living_room")
    with WorldRunner(sim, args.time_scale):
        server = serve_arcos(sim, aux1=EchoDevice())
        with ArcosBase.open(server.path) as base:
            base.send(Command.RVEL, 10)
            base.send(Command.VEL, 50)
            count, t0 = base.sip_count, time.monotonic()
            time.sleep(args.seconds)
            rate = (base.sip_count - count) / (time.monotonic() - t0)
            print(
                f"SIP rate through the pty: {rate:.2f} SIPs/s over {args.seconds:g} s "
                f"(firmware cycle 100 ms; {base.protocol_errors} protocol errors)"
            )
            base.stop()
            time.sleep(0.5)

            aux = base.aux_transport()
            trips = []
            for _ in range(args.trips):
                t = time.perf_counter()
                aux.write(b"\xff\x30\x30\x00\x63\xef")
                assert len(aux.read(6, 1.0)) == 6
                trips.append(time.perf_counter() - t)
            print(f"AUX round trip (TTY2 6 bytes -> echo -> GETAUX/SERAUX): {_ms(trips)}")

            latencies = []
            for i in range(min(args.trips, 20)):
                time.sleep(0.35)  # let the robot stop
                seq = base.sip_count
                t = time.perf_counter()
                base.send(Command.VEL, 100 if i % 2 else -100)
                while True:
                    sip = base._await_sip(seq, base.clock.now() + 2.0, "bench")
                    seq = base.sip_count
                    if sip.moving:
                        break
                latencies.append(time.perf_counter() - t)
                base.send(Command.STOP)
            print(f"VEL -> first SIP showing motion: {_ms(latencies)}")
        server.stop()
    _virtual_time(args.virtual_seconds)


def _virtual_time(seconds: float) -> None:
    clock = ManualClock()
    sim, _ = make_sim_robot("living_room")
    link = MemoryLink(clock, "arcos line")
    with (
        WorldRunner(sim, clock=clock),
        serve_arcos(sim, link, clock=clock),
        ArcosBase(lambda: link.transport("ARCOS base"), clock=clock) as base,
    ):
        wall = time.perf_counter()
        began = clock.now()
        base.drive(0.1, math.radians(10), seconds)
        virtual = clock.now() - began
        wall = time.perf_counter() - wall
    print(
        f"virtual time (ManualClock, memory line, world at 1x): {virtual:.1f} s of driving "
        f"in {wall:.2f} s wall, {virtual / wall:.1f}x real time ({base.sip_count} SIPs)"
    )


if __name__ == "__main__":
    main()
