"""The reference map of a scene cut at the laser's height: every kind of geom against MuJoCo's own
geometry, the living room's known features, MuJoCo's rays, and a map built from a drive."""

import math
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from twin.core.devices import LaserMount, Scan
from twin.core.errors import InputError
from twin.core.geometry import Pose2D
from twin.nav.mapping import MapBuilder, map_agreement, wheel_odometry
from twin.nav.maps import load_map, save_map
from twin.nav.raycast import laser_pose, lms200_angles, raycast
from twin.nav.scan_matching import CorrelativeScanMatcher
from twin.sim.scene_map import scene_map
from twin.sim.world import World

sys.path.insert(0, str(Path(__file__).parent))
from test_mapping import drive

SHAPES = """
<mujoco>
  <compiler angle="radian"/>
  <asset>
    <mesh name="prism" vertex="0 0 0  0.4 0 0  0 0.3 0  0 0 0.6  0.4 0 0.6  0 0.3 0.6"/>
  </asset>
  <worldbody>
    <geom name="floor" type="plane" pos="2 2 0" size="2 2 0.1"/>
    <geom name="box" type="box" pos="0.6 0.6 0.3" size="0.3 0.1 0.2" euler="0 0 0.5"/>
    <geom name="tilted_box" type="box" pos="1.4 1.4 0.35" size="0.2 0.15 0.2" euler="0.4 0.3 0.2"/>
    <geom name="ball" type="sphere" pos="2.0 0.6 0.4" size="0.2"/>
    <geom name="egg" type="ellipsoid" pos="3.0 0.6 0.35" size="0.3 0.15 0.2" euler="0.3 0.2 0.7"/>
    <geom name="pipe" type="capsule" fromto="0.4 2.0 0.1 1.4 2.4 0.5" size="0.08"/>
    <geom name="drum" type="cylinder" pos="2.4 2.0 0.3" size="0.25 0.3" euler="0.6 0 0"/>
    <geom name="wedge" type="mesh" mesh="prism" pos="3.0 2.0 0" euler="0 0 0.4"/>
    <geom name="wall" type="plane" pos="3.9 2 0" zaxis="-1 0 0" size="2 2 0.1"/>
    <geom name="shelf" type="box" pos="1 3.4 0.7" size="0.3 0.2 0.02"/>
    <geom name="ghost" type="box" pos="2 3.4 0.3" size="0.2 0.2 0.2" rgba="1 1 1 0"/>
    <geom name="hidden" type="box" pos="3 3.4 0.3" size="0.2 0.2 0.2" group="3"/>
    <body name="rover" pos="0.5 3.4 0">
      <freejoint/>
      <geom type="box" size="0.1 0.1 0.5" pos="0 0 0.5"/>
    </body>
  </worldbody>
</mujoco>
"""
HEIGHT = 0.3


def inside(model, data, geom, points):
    """Whether world points (n, 3) are inside a geom, from MuJoCo's pose and size of it."""
    local = (points - data.geom_xpos[geom]) @ data.geom_xmat[geom].reshape(3, 3)
    size, kind, types = model.geom_size[geom], model.geom_type[geom], mujoco.mjtGeom
    if kind == types.mjGEOM_BOX:
        return np.all(np.abs(local) <= size, axis=1)
    if kind == types.mjGEOM_SPHERE:
        return np.linalg.norm(local, axis=1) <= size[0]
    if kind == types.mjGEOM_ELLIPSOID:
        return np.sum((local / size) ** 2, axis=1) <= 1.0
    if kind == types.mjGEOM_CAPSULE:
        along = np.clip(local[:, 2], -size[1], size[1])
        return np.hypot(np.hypot(local[:, 0], local[:, 1]), local[:, 2] - along) <= size[0]
    if kind == types.mjGEOM_CYLINDER:
        return (np.hypot(local[:, 0], local[:, 1]) <= size[0]) & (np.abs(local[:, 2]) <= size[1])
    if kind == types.mjGEOM_PLANE:
        return local[:, 2] <= 0.0
    raise AssertionError(kind)


def wedge_inside(points):
    """The mesh: a right triangle (0.4 x 0.3 m) extruded 0.6 m up, turned 0.4 rad, at (3, 2)."""
    c, s = math.cos(0.4), math.sin(0.4)
    u = c * (points[:, 0] - 3.0) + s * (points[:, 1] - 2.0)
    v = -s * (points[:, 0] - 3.0) + c * (points[:, 1] - 2.0)
    return (u >= 0) & (v >= 0) & (u / 0.4 + v / 0.3 <= 1.0)


@pytest.fixture(scope="module")
def shapes(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "shapes.xml"
    path.write_text(SHAPES)
    return World(path)


def test_every_kind_of_geom_is_cut_where_mujoco_has_it(shapes):
    model, data = shapes.model, shapes.data
    res, sub = 0.02, 8
    cut = scene_map(shapes, HEIGHT, res, margin=0.0)
    assert cut.shape == (200, 200) and cut.origin == (0.0, 0.0, 0.0)
    # sub x sub sample points in every cell, at the cutting height
    ny, nx = cut.shape
    offsets = (np.arange(sub) + 0.5) / sub * res
    xs = (np.arange(nx)[:, None] * res + offsets).ravel()
    ys = (np.arange(ny)[:, None] * res + offsets).ravel()
    gx, gy = np.meshgrid(xs, ys)
    points = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, HEIGHT)], axis=1)
    solid = wedge_inside(points)
    for name in ("box", "tilted_box", "ball", "egg", "pipe", "drum", "wall"):
        solid |= inside(model, data, model.geom(name).id, points)
    touched = solid.reshape(ny, sub, nx, sub).any(axis=(1, 3))
    # every cell any part of a shape is in is occupied (the map never misses an obstacle) ...
    assert not (touched & ~cut.occupied).any()
    # ... and no cell is occupied farther than a cell from one
    near = touched.copy()
    near[1:] |= touched[:-1]
    near[:-1] |= touched[1:]
    near[:, 1:] |= near[:, :-1].copy()
    near[:, :-1] |= near[:, 1:].copy()
    assert not (cut.occupied & ~near).any()
    # each shape is there: the wall's solid side, the capsule's and the mesh's slices
    assert cut.occupied[:, 196:].all() and not cut.occupied[:, 190:195].any()
    for x, y in [(0.9, 2.15), (3.05, 2.05), (2.0, 0.6), (3.0, 0.6), (2.4, 2.0), (1.4, 1.4)]:
        row, col = cut.cell_of(x, y)
        assert cut.occupied[row, col], (x, y)
    # what does not reach the plane, is transparent, hidden or moves is not in the map
    for x, y in [(1.0, 3.4), (2.0, 3.4), (3.0, 3.4), (0.5, 3.4)]:
        row, col = cut.cell_of(x, y)
        assert cut.free[row - 3 : row + 4, col - 3 : col + 4].all(), (x, y)


def test_a_height_field_is_refused_in_one_line(tmp_path):
    path = tmp_path / "terrain.xml"
    path.write_text(
        '<mujoco><asset><hfield name="h" nrow="2" ncol="2" size="1 1 0.5 0.1"/></asset>'
        '<worldbody><geom name="floor" type="plane" size="2 2 0.1"/>'
        '<geom name="hill" type="hfield" hfield="h"/></worldbody></mujoco>'
    )
    with pytest.raises(InputError, match="'hill' is a hfield") as caught:
        scene_map(World(path))
    assert "\n" not in str(caught.value)
    with pytest.raises(InputError, match="height"):
        scene_map(World(path), height=-0.3)


# -- the living room ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def living_room():
    world = World("living_room")
    return world, scene_map(world)


def blob(occupancy_map, x, y, reach=0.1):
    """The occupied cells within ``reach`` metres (a square) of (x, y), and whether the square's
    rim is free."""
    row, col = occupancy_map.cell_of(x, y)
    k = round(reach / occupancy_map.resolution)
    window = occupancy_map.occupied[row - k : row + k + 1, col - k : col + k + 1]
    rim = np.ones_like(window)
    rim[1:-1, 1:-1] = False
    return int(window.sum()), bool(not window[rim].any())


def test_the_living_room_map_covers_the_room_and_its_walls(living_room):
    _, cut = living_room
    assert cut.resolution == 0.05 and cut.origin == pytest.approx((-0.1, -0.1, 0.0))
    assert cut.shape == (124, 94)  # 4.5 m x 6 m grown by 0.1 m on every side
    # the walls are lines of two cells just outside the floor; the floor's edge cells are free
    for wall in (cut.occupied[:, :2], cut.occupied[:, -2:], cut.occupied[:2], cut.occupied[-2:]):
        assert wall.all()
    row, col = cut.cell_of(np.array([1.0, 2.0, 0.025, 4.475]), np.array([0.025, 5.975, 3.2, 3.2]))
    assert cut.free[row, col].all()


def test_table_and_chair_legs_are_small_blobs(living_room):
    _, cut = living_room
    legs = [(3.5 + sx * 0.55, 5.15 + sy * 0.35) for sx in (-1, 1) for sy in (-1, 1)]  # table
    legs += [(1.6 + sx * 0.26, 4.7 + sy * 0.45) for sx in (-1, 1) for sy in (-1, 1)]  # coffee
    legs += [(3.65 + sx * 0.24, 3.0 + sy * 0.24) for sx in (-1, 1) for sy in (-1, 1)]  # chair
    legs.append((0.3, 0.3))  # the floor lamp's pole
    for x, y in legs:
        cells, isolated = blob(cut, x, y)
        assert 1 <= cells <= 4 and isolated, (x, y, cells)
    # under the chair's seat (0.36 m up) and the tables' tops the laser sees through
    for x, y in [(3.65, 3.0), (3.5, 5.15), (1.6, 4.7)]:
        assert blob(cut, x, y, reach=0.15)[0] == 0


def test_the_sofa_front_is_a_line_at_its_face(living_room):
    _, cut = living_room
    # the sofa's base (0.4 m high) spans x 0.05 .. 0.95, y 3.7 .. 5.7: its front face at 0.95
    rows = np.arange(*cut.cell_of(0.5, 3.725)[0:1], cut.cell_of(0.5, 5.675)[0] + 1)
    front = cut.cell_of(0.925, 0.0)[1]
    assert cut.occupied[rows, front].all() and cut.free[rows, front + 1].all()
    assert cut.occupied[rows, cut.cell_of(0.5, 0)[1]].all()  # a solid cross-section
    assert cut.free[cut.cell_of(0.5, 3.675)[0], 3:front].all()  # and free in front of its end


def test_other_furniture_where_the_scene_puts_it(living_room):
    world, cut = living_room
    cells, isolated = blob(cut, 4.15, 0.4, reach=0.25)  # the plant's pot, 0.32 m across
    assert isolated and 30 <= cells <= 60
    assert cut.occupied[cut.cell_of(4.3, 1.6)].item()  # the TV cabinet
    assert cut.occupied[cut.cell_of(0.2, 1.8)].item()  # the sideboard
    assert cut.free[cut.cell_of(1.5, 5.0)].item()  # the target on the coffee table: too high
    # the door (decoration) stands 5 mm in front of the right wall
    door = cut.cell_of(4.4975, 4.7)
    assert cut.occupied[door].item()
    assert cut.free[door[0], door[1] - 1].item()
    without_decor = scene_map(world, groups=(0,))
    assert not without_decor.occupied[door].item()
    # a body left out leaves no trace
    no_chair = scene_map(world, exclude_bodies=["chair"])
    assert blob(no_chair, 3.41, 2.76)[0] == 0
    assert np.count_nonzero(cut.occupied & ~no_chair.occupied) == 16


def test_the_scene_map_round_trips_through_map_server_files(living_room, tmp_path):
    _, cut = living_room
    loaded = load_map(save_map(cut, tmp_path / "living_room.yaml"))
    np.testing.assert_array_equal(loaded.occupied, cut.occupied)
    np.testing.assert_array_equal(loaded.free, cut.free)
    assert loaded.origin == pytest.approx(cut.origin)


def robot_out_of_the_way(world):
    """Move the robot's free joint far outside the room, so rays see the scene only."""
    joint = world.model.joint("base")
    world.data.qpos[joint.qposadr[0] : joint.qposadr[0] + 3] = (100.0, 100.0, 0.0)
    world.forward()


def mujoco_ranges(world, sensor: Pose2D, angles: np.ndarray, max_range: float = 8.0):
    """Ranges of rays cast by MuJoCo at the laser's height from ``sensor`` (NaN: no hit)."""
    bearings = angles + sensor.yaw
    directions = np.stack([np.cos(bearings), np.sin(bearings), np.zeros_like(bearings)], axis=1)
    geoms = np.zeros(len(angles), dtype=np.int32)
    dist = np.zeros(len(angles))
    mujoco.mj_multiRay(
        world.model,
        world.data,
        np.array([sensor.x, sensor.y, 0.30]),
        directions.ravel(),
        np.array([1, 1, 0, 0, 0, 0], dtype=np.uint8),
        1,
        -1,
        geoms,
        dist,
        None,
        len(angles),
        max_range,
    )
    return np.where((geoms >= 0) & (dist > 0) & (dist < max_range), dist, np.nan)


# free spots to cast from, per scene: in the apartment one in each room and its doors' reach
SENSOR_SPOTS = {
    "living_room": [(2.25, 2.5), (1.2, 3.0), (3.0, 4.0), (2.5, 1.0), (2.2, 5.6)],
    "apartment": [(2.25, 2.5), (1.0, 6.9), (5.6, 6.6), (8.6, 5.0), (6.2, 2.2)],
}


@pytest.fixture(scope="module", params=sorted(SENSOR_SPOTS))
def any_scene(request, living_room):
    """(world, its scene map, spots to cast from) for each scene the invariants hold in."""
    if request.param == "living_room":
        return (*living_room, SENSOR_SPOTS["living_room"])
    world = World(request.param)
    return world, scene_map(world), SENSOR_SPOTS[request.param]


def test_mujoco_rays_end_on_occupied_cells(any_scene):
    world, cut, spots = any_scene
    robot_out_of_the_way(world)
    angles = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    for x, y in spots:
        sensor = Pose2D(x, y, 0.0)
        truth = mujoco_ranges(world, sensor, angles, 15.0)
        assert np.isfinite(truth).all()  # a closed room (or flat: rooms behind open doors)
        ends = np.stack([x + (truth + 1e-4) * np.cos(angles), y + (truth + 1e-4) * np.sin(angles)])
        row, col = cut.cell_of(ends[0], ends[1])
        assert cut.occupied[row, col].all()  # every return lies on something the map has
        mapped = raycast(cut, sensor, angles, 15.0)
        assert (mapped <= truth + 1e-6).all()  # the map is conservative ...
        # ... and never by a phantom: where the map stops a beam, MuJoCo has geometry within
        # a cell's diagonal of that point
        fan = np.linspace(-math.pi, math.pi, 72, endpoint=False)
        diagonal = math.sqrt(2.0) * cut.resolution + 1e-6
        for k in np.nonzero(mapped < truth - 1e-3)[0]:
            stop = Pose2D(
                x + mapped[k] * math.cos(angles[k]), y + mapped[k] * math.sin(angles[k]), 0
            )
            assert np.isfinite(mujoco_ranges(world, stop, fan, diagonal)).any(), k
        # for most beams the map's first occupied cell is the return's cell or its neighbour;
        # the others pass within a cell of a thin leg or an obstacle's corner
        first = cut.cell_of(
            x + (mapped + 1e-6) * np.cos(angles), y + (mapped + 1e-6) * np.sin(angles)
        )
        apart = np.maximum(np.abs(first[0] - row), np.abs(first[1] - col))
        assert np.mean(apart <= 1) > 0.85


def test_a_drive_through_the_living_room_builds_its_map(living_room):
    """Scans cast by MuJoCo along a drive, 1 % wheel error on the odometry: the builder's map
    agrees with the scene's, its path stays within centimetres of the truth."""
    world, reference = living_room
    robot_out_of_the_way(world)
    mount = LaserMount(x=0.1, y=0.0, z=0.30, yaw=0.0)
    truth = drive(
        [
            (2.25, 2.5, math.pi / 2),
            (2.25, 1.0),
            (3.6, 1.0),
            (3.0, 2.3),
            (2.6, 4.0),
            (2.3, 5.5),
            (2.3, 3.3),
            (1.2, 3.3),
            (1.2, 1.4),
            (2.25, 1.6),
        ]
    )
    rng = np.random.default_rng(7)
    angles = lms200_angles(181)
    scans = []
    for pose in truth:
        ranges = mujoco_ranges(world, laser_pose(pose, mount), angles)
        scans.append(Scan(angles, ranges + rng.normal(0.0, 0.01, ranges.shape), 0.0, 8.0))
    odometry = wheel_odometry(truth, right_scale=1.01)
    builder = MapBuilder((-0.5, -0.5, 5.0, 6.5), matcher=CorrelativeScanMatcher(mount=mount))
    for pose, scan in zip(odometry, scans, strict=True):
        builder.add(pose, scan)
    drift = max(o.distance_to(t) for o, t in zip(odometry, truth, strict=True))
    errors = [c.distance_to(t) for c, t in zip(builder.trajectory, truth, strict=True)]
    assert drift > 0.5
    assert max(errors) < 0.04
    score = map_agreement(builder.to_map(), reference, tolerance_m=0.05)
    assert score.precision > 0.98 and score.recall > 0.9
