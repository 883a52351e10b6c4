"""Camera calibration with OpenCV's chessboard method, and where its result is kept.

Frames come from a camera built from a config (a real camera: the user moves a printed board in
front of it between grabs; the twin's calibration stage, ``scenes/calibration_board.xml``: the
board moves itself through seeded poses) or from a folder of images. Each frame's inner corners
are found (``cv2.findChessboardCorners``), refined to a tenth of a pixel (``cornerSubPix``), and
``cv2.calibrateCamera`` fits fx, fy, cx, cy, k1, k2, p1, p2 with k3 held at 0: at the VC-C4's
47.5 degrees the frame reaches only r = 0.55 in normalized units, where r^6 is too small for k3
to be told apart from k2 (freeing it trades one against the other and the fit extrapolates
badly at the corners).

The result goes into the config's ``[robot.camera]`` table as ``intrinsics`` and ``distortion``
by editing the TOML *text* (two lines replaced or added, nothing else touched), written
atomically. That keeps the user's comments and layout, which a parse-and-dump would lose, and
keeps the camera's numbers in the one file that describes the robot rather than in a second
file the config would have to name and that could be lost or mixed up between robots.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np

from twin.core.errors import InputError
from twin.core.geometry import CameraModel
from twin.core.lens import Lens
from twin.core.store import write_text_atomic

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
MIN_VIEWS = 5  # fewer views than this leave the principal point and distortion ill-determined
BOARD_BODY = "calibration_board"  # the twin's board (a mocap body)


@dataclass(frozen=True)
class Calibration:
    """A fitted lens and how well it fits: ``rms_px`` is OpenCV's RMS reprojection error over
    every corner of every used view; ``views`` how many frames showed the board (of ``frames``)."""

    lens: Lens
    width: int
    height: int
    rms_px: float
    views: int
    frames: int

    @property
    def camera(self) -> CameraModel:
        return CameraModel.with_lens(self.width, self.height, self.lens)

    def summary(self) -> str:
        camera = self.camera
        k = self.lens
        return (
            f"{self.views} of {self.frames} frames showed the board; RMS reprojection error "
            f"{self.rms_px:.3f} px\n"
            f"field of view {math.degrees(camera.hfov):.2f} x {math.degrees(camera.vfov):.2f} deg "
            f"({self.width} x {self.height} px)\n"
            f"intrinsics fx {k.fx:.2f}, fy {k.fy:.2f}, cx {k.cx:.2f}, cy {k.cy:.2f} px\n"
            f"distortion k1 {k.k1:.4f}, k2 {k.k2:.4f}, p1 {k.p1:.5f}, p2 {k.p2:.5f}, k3 {k.k3:.4f}"
        )


def parse_pattern(text: str) -> tuple[int, int]:
    """'9x6' -> (9, 6): inner corners per row and per column."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not match or min(int(match[1]), int(match[2])) < 2:
        raise InputError(f"--pattern {text!r}: give the inner corners as COLSxROWS, e.g. 9x6")
    return int(match[1]), int(match[2])


def find_corners(image: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """The board's inner corners (n, 1, 2) float32 in OpenCV pixels, refined to subpixels, or
    None if the whole board is not in view."""
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, pattern, flags=flags)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    return cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), criteria)


def calibrate(
    frames: list[np.ndarray], pattern: tuple[int, int], square_m: float = 0.06
) -> Calibration:
    """Fit the lens to ``frames`` (H x W x 3 RGB or H x W grey, all one size) of a chessboard
    with ``pattern`` inner corners of ``square_m`` metres (the size scales only the board
    poses, not the lens). Raises ``InputError`` if too few frames show the board."""
    if not frames:
        raise InputError("no frames to calibrate from; give images of the chessboard")
    sizes = {f.shape[:2] for f in frames}
    if len(sizes) != 1:
        raise InputError(f"the frames differ in size ({sorted(sizes)}); calibrate one size")
    height, width = frames[0].shape[:2]
    board = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    board[:, :2] = np.mgrid[0 : pattern[0], 0 : pattern[1]].T.reshape(-1, 2) * square_m
    image_points = [c for c in (find_corners(f, pattern) for f in frames) if c is not None]
    if len(image_points) < MIN_VIEWS:
        raise InputError(
            f"the {pattern[0]}x{pattern[1]} chessboard was found in {len(image_points)} of "
            f"{len(frames)} frames, at least {MIN_VIEWS} are needed; check --pattern (inner "
            "corners) and show the whole board, tilted, all over the frame"
        )
    flags = cv2.CALIB_FIX_K3
    rms, matrix, coefficients, _, _ = cv2.calibrateCamera(
        [board] * len(image_points), image_points, (width, height), None, None, flags=flags
    )
    lens = Lens.from_opencv(matrix, coefficients)
    return Calibration(lens, width, height, float(rms), len(image_points), len(frames))


# -- where frames come from ------------------------------------------------------------------


def frames_from_folder(folder: Path) -> list[np.ndarray]:
    """Every image in ``folder`` (sorted by name), as RGB."""
    if not folder.exists():
        raise InputError(f"--images {folder}: no such folder")
    if not folder.is_dir():
        raise InputError(f"--images {folder}: is not a folder; give the folder of board images")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not paths:
        raise InputError(
            f"--images {folder}: no images ({', '.join(IMAGE_SUFFIXES)}) in it; save the "
            "board's frames there"
        )
    frames = []
    for path in paths:
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if image is None:
            raise InputError(f"{path}: not an image OpenCV can read; remove it or convert it")
        frames.append(np.ascontiguousarray(image[..., ::-1]))
    return frames


def board_poses(count: int, seed: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Where the twin's board goes, relative to the camera: (centre, rotation) pairs with the
    centre in the camera's frame (x right, y up, z back, as MuJoCo's cameras) and the rotation
    the board's axes in that frame. The board sweeps the frame (centres out to the edges, where
    the distortion shows) at 1.1-1.8 m, turned up to 40 degrees about both of its axes, as the
    OpenCV tutorial asks of a person holding it: the steep views pin down the focal length (at
    up to 30 degrees it came out 0.2 % off in the twin, at 40 within 0.05 %)."""
    rng = np.random.default_rng(seed)
    spots = [(0.0, 0.0), (-0.22, 0.0), (0.22, 0.0), (0.0, -0.15), (0.0, 0.15), (-0.2, -0.14),
             (0.2, -0.14), (-0.2, 0.14), (0.2, 0.14), (-0.12, 0.06), (0.12, -0.06)]  # fmt: skip
    for i in range(count):
        sx, sy = spots[i % len(spots)]
        distance = rng.uniform(1.1, 1.8)
        # tan of the angle off the axis; the board (0.72 x 0.54 m) must fit inside the frame
        centre = np.array([sx * distance, sy * distance, -distance])
        yaw, pitch = np.radians(rng.uniform(-40.0, 40.0, size=2))
        roll = np.radians(rng.uniform(-10.0, 10.0))
        yield centre, _rotation(yaw, pitch, roll)


def _rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Board axes in the camera frame: facing the camera (its +z toward the camera's +z),
    turned by yaw about y, pitch about x, roll about z."""
    cy, sy, cp, sp, cr, sr = (math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch),
                              math.cos(roll), math.sin(roll))  # fmt: skip
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    return ry @ rx @ rz


def frames_from_camera(
    camera,  # twin.core.devices.Camera, connected
    sim,  # twin.sim.robot.SimRobot | None: the twin, which can move the board itself
    count: int,
    interval_s: float,
    seed: int,
    say: Callable[[str], None],
) -> list[np.ndarray]:
    """``count`` frames from ``camera``. In the twin, the scene's board is put at a new
    pose (``board_poses``) before each grab; with a real camera, the user moves the board
    during the ``interval_s`` seconds before each grab."""
    mover = _board_mover(sim) if sim is not None else None
    poses = board_poses(count, seed)
    frames = []
    for i in range(count):
        if mover is not None:
            mover(*next(poses))
        else:
            say(f"frame {i + 1}/{count} in {interval_s:g} s: hold the board still, elsewhere")
            _sleep(camera, interval_s)
        frames.append(camera.grab().image)
    return frames


def _sleep(camera, seconds: float) -> None:
    clock = getattr(camera, "clock", None)
    if clock is not None:
        clock.sleep(seconds)
    else:  # a camera without its own clock: real time
        import time

        time.sleep(seconds)


def _board_mover(sim) -> Callable[[np.ndarray, np.ndarray], None]:
    """Put the twin's board at a pose given in the head camera's frame (``board_poses``)."""
    import mujoco

    world = sim.world
    body = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_BODY, BOARD_BODY)
    mocap = int(world.model.body_mocapid[body]) if body >= 0 else -1
    if mocap < 0:
        raise InputError(
            f"the scene {world.path} has no movable board (a mocap body {BOARD_BODY!r}); "
            "calibrate in the twin with --config calibration_board, or give --images"
        )

    def move(centre: np.ndarray, axes: np.ndarray) -> None:
        with sim.lock:
            position = sim.world.data.cam_xpos[sim.camera_id].copy()
            frame = sim.world.data.cam_xmat[sim.camera_id].reshape(3, 3).copy()
            world_axes = frame @ axes
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, world_axes.reshape(-1))
            sim.world.data.mocap_pos[mocap] = position + frame @ centre
            sim.world.data.mocap_quat[mocap] = quat
            sim.world.forward()

    return move


# -- where the result is kept ------------------------------------------------------------------

_TABLE = re.compile(r"^\s*\[\s*robot\s*\.\s*camera\s*\]\s*(#.*)?$")
_ANY_TABLE = re.compile(r"^\s*\[")
_NOTE = "# calibrated by twin calibrate"


def _number(value: float) -> str:
    return f"{value:.8g}"


def with_calibration(text: str, calibration: Calibration, source: str) -> str:
    """``text`` (a config's TOML) with ``[robot.camera]``'s ``intrinsics`` and ``distortion``
    set to the calibration's: existing lines replaced in place, or added at the end of the
    table's keys with a comment saying where they came from. Nothing else changes."""
    lines = text.splitlines(keepends=True)
    start = next((i for i, line in enumerate(lines) if _TABLE.match(line)), None)
    if start is None:
        raise InputError(
            "the config has no [robot.camera] table to write the calibration into; add one"
        )
    end = next((i for i in range(start + 1, len(lines)) if _ANY_TABLE.match(lines[i])), len(lines))
    lens = calibration.lens
    values = {
        "intrinsics": "[" + ", ".join(_number(v) for v in lens.intrinsics) + "]",
        "distortion": "[" + ", ".join(_number(v) for v in lens.coefficients) + "]",
    }
    body = lines[start + 1 : end]
    note = f"# calibrated by twin calibrate ({source}): {_note(calibration)}\n"
    old_note = next((i for i, line in enumerate(body) if line.startswith(_NOTE)), None)
    if old_note is not None:
        body[old_note] = note
    for key, value in values.items():
        pattern = re.compile(rf"^(\s*){key}\s*=")
        at = next((i for i, line in enumerate(body) if pattern.match(line)), None)
        if at is not None:
            stop = at  # a multi-line array runs to its closing bracket
            while "]" not in body[stop].split("#", 1)[0] and stop + 1 < len(body):
                stop += 1
            comment = ""
            tail = body[stop].split("]", 1)[1] if "]" in body[stop] else ""
            if "#" in tail:
                comment = "  #" + tail.split("#", 1)[1].rstrip("\n")
            indent = pattern.match(body[at])[1]
            body[at : stop + 1] = [f"{indent}{key} = {value}{comment}\n"]
        else:
            last = max((i for i, line in enumerate(body) if line.strip()), default=-1)
            if last >= 0 and not body[last].endswith("\n"):
                body[last] += "\n"
            added = [f"{key} = {value}\n"]
            if old_note is None:
                added.insert(0, note)
                old_note = last + 1
            body[last + 1 : last + 1] = added
    new = "".join([*lines[: start + 1], *body, *lines[end:]])
    _check_written(new, lens)
    return new


def _note(calibration: Calibration) -> str:
    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    return f"{when}, RMS {calibration.rms_px:.3f} px over {calibration.views} views"


def _check_written(text: str, lens: Lens) -> None:
    """The edited text must parse and give back the lens (to the digits written)."""
    try:
        camera = tomllib.loads(text)["robot"]["camera"]
    except (tomllib.TOMLDecodeError, KeyError) as exc:
        raise InputError(
            f"writing the calibration would break the config ({exc}); add intrinsics and "
            "distortion to [robot.camera] by hand"
        ) from exc
    got = Lens.from_lists(tuple(camera["intrinsics"]), tuple(camera["distortion"]))
    want = np.array([*lens.intrinsics, *lens.coefficients])
    if not np.allclose([*got.intrinsics, *got.coefficients], want, rtol=1e-6, atol=1e-12):
        raise InputError("the calibration did not read back from the edited config; not written")


def write_calibration(config_path: Path, calibration: Calibration, source: str) -> Path:
    """Write the calibration into ``config_path``'s ``[robot.camera]`` table, atomically."""
    text = config_path.read_text(encoding="utf-8")
    return write_text_atomic(config_path, with_calibration(text, calibration, source))
