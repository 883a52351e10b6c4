"""``twin hw probe``: which serial ports and cameras there are, and what answers on each.

Nothing moves: the ARCOS check is the SYNC handshake alone (the robot is not opened), the VC-C4
check an operation-status query, the SICK LMS check a type and a status request at 9600 and at
38400 baud (its stream and settings are left as they are); a camera is opened for one frame.
Every check has a short timeout, so a silent port costs about two seconds.
"""

from __future__ import annotations

import argparse
import glob


def register(hw_subparsers: argparse._SubParsersAction) -> None:
    parser = hw_subparsers.add_parser(
        "probe",
        help="list serial ports and cameras, and what answers on them",
        description="Lists the serial ports and video devices and asks each what it is: an "
        "ARCOS robot (SYNC handshake, nothing opened), a Canon VC-C4 (status query), a SICK "
        "LMS200 laser (type and status requests at 9600 and 38400 baud), a camera (one "
        "frame). Add ports the system does not list (e.g. the serial twins' pseudo-terminals) "
        "with --port.",
    )
    parser.add_argument("--port", action="append", default=[], help="also probe this port")
    parser.add_argument("--camera", action="append", default=[], help="also probe this camera")
    parser.add_argument("--timeout", type=float, default=0.4, help="seconds per reply (0.4)")
    parser.set_defaults(handler=run)


def serial_ports(extra: list[str]) -> list[str]:
    from serial.tools import list_ports

    found = [p.device for p in list_ports.comports()]
    return list(dict.fromkeys([*found, *extra]))


def probe_serial(port: str, timeout: float) -> str:
    """What answers on ``port``, in one line."""
    from hardware.arcos import ArcosBase
    from hardware.lms2xx import LMS2xx
    from hardware.vcc4 import VCC4
    from twin.core.devices import DeviceError

    try:
        name, kind, sub = ArcosBase.open(port, sync_attempts=3, reply_timeout=timeout).identify()
    except DeviceError as exc:
        if "no such port" in str(exc) or "permission" in str(exc) or "busy" in str(exc):
            return str(exc)
    else:
        return f"ARCOS robot {name!r} ({kind} {sub})"
    try:
        return VCC4.open(port, answer_timeout=timeout, retries=0).identify()
    except DeviceError:
        pass
    try:
        return LMS2xx.open(port).identify(rates=(9600, 38400), timeout=timeout)
    except DeviceError:
        return (
            "no ARCOS robot and no VC-C4 answers, nor a SICK LMS at 9600 or 38400 baud "
            "(check power, cable, baud)"
        )


def probe_camera(device: str) -> str:
    from hardware.opencv_camera import OpenCVCamera
    from twin.core.devices import DeviceError

    try:
        with OpenCVCamera(device, reconnect_attempts=0) as camera:
            frame = camera.grab()
    except DeviceError as exc:
        return str(exc)
    return f"delivers frames (resized to {frame.image.shape[1]}x{frame.image.shape[0]})"


def run(args: argparse.Namespace) -> int:
    ports = serial_ports(args.port)
    print(f"serial ports ({len(ports)}):" if ports else "serial ports: none found")
    for port in ports:
        print(f"  {port}: {probe_serial(port, args.timeout)}")
    cameras = list(dict.fromkeys([*sorted(glob.glob("/dev/video*")), *args.camera]))
    print(f"cameras ({len(cameras)}):" if cameras else "cameras: none found (no /dev/video*)")
    for camera in cameras:
        print(f"  {camera}: {probe_camera(camera)}")
    return 0
