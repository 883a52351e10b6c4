"""Visibility from depth: rendered depth in the twin, the rule that turns depth into column
profiles (tested on exactly ray-cast boxes), the room model rendered at the robot's pose, and
depth from a laser map."""

from __future__ import annotations

import math

import numpy as np
import pytest

# isort: off
import twin.sim  # noqa: F401  (must come first: it selects headless GL before mujoco loads)
import mujoco

# isort: on
from twin.core.errors import InputError
from twin.core.geometry import CameraModel, Pose2D
from twin.core.visibility import SupportLevels, visibility_from_depth
from twin.nav.maps import OccupancyMap
from twin.nav.visibility import depth_from_map
from twin.sim.model_view import ModelDepth
from twin.sim.render import FrameRenderer
from twin.sim.robot import CAMERA_NAME, SimCamera, make_sim_robot

CAMERA = CameraModel()
SPANS = np.stack([np.arange(19) * 16.0, np.arange(19) * 16.0 + 32.0], axis=1)  # 32 px, stride 16
CENTRE = [8, 9, 10]  # the patch columns around the optical axis
FLOOR = SupportLevels(0.0, 0.0, 1.0, np.zeros((1, 1, 1)))  # outside its grid: the floor too


def _levels(*heights: float) -> SupportLevels:
    """The same support heights in every cell of a 20 m square around the origin."""
    return SupportLevels(-10.0, -10.0, 1.0, np.broadcast_to(heights, (20, 20, len(heights))))


Box = tuple[float, float, float, float, float, float]  # x0, y0, z0, x1, y1, z1 (metres)


def _box_depth(boxes: list[Box], *, axis: float = 0.0, tilt: float = 0.0) -> np.ndarray:
    """Exact depth along each pixel's ray for a camera at (0, 0, 1) m over a floor with boxes."""
    f, w, h = CAMERA.focal_px, CAMERA.width, CAMERA.height
    left = ((w / 2 - (np.arange(w) + 0.5)) / f)[None, :, None]
    up = ((h / 2 - (np.arange(h) + 0.5)) / f)[:, None, None]
    ca, sa, ct, st = math.cos(axis), math.sin(axis), math.cos(tilt), math.sin(tilt)
    ray = (
        np.array([ct * ca, ct * sa, st])
        + left * np.array([-sa, ca, 0.0])
        + up * np.array([-st * ca, -st * sa, ct])
    )
    ray /= np.linalg.norm(ray, axis=2, keepdims=True)
    start = np.array([0.0, 0.0, 1.0])
    with np.errstate(divide="ignore", invalid="ignore"):
        best = np.where(ray[..., 2] < 0, -1.0 / ray[..., 2], np.inf)
        for box in boxes:
            a = (np.array(box[:3]) - start) / ray
            b = (np.array(box[3:]) - start) / ray
            near = np.minimum(a, b).max(axis=2)
            far = np.maximum(a, b).min(axis=2)
            best = np.where((near <= far) & (near > 0), np.minimum(best, near), best)
    return np.where(np.isfinite(best), best, np.nan)


def _profiles(depth: np.ndarray, supports: SupportLevels, **kw: float) -> np.ndarray:
    args = {"tilt": 0.0, "object_height": 0.2, "reach": 8.0}
    args.update(kw)
    return visibility_from_depth(
        depth,
        CAMERA,
        SPANS,
        origin=(0.0, 0.0),
        axis=0.0,
        camera_height=1.0,
        supports=supports,
        **args,
    ).profiles


def _bins(lo: float, hi: float, step: float = 0.05) -> slice:
    """Bins whose centres lie in [lo, hi] metres."""
    return slice(math.ceil(lo / step - 0.5), math.floor(hi / step - 0.5) + 1)


# -- the rule ------------------------------------------------------------------------------------
def test_open_room_is_visible_within_the_vertical_field_of_view() -> None:
    depth = _box_depth([])
    anywhere = _profiles(depth, _levels(0.0, 0.4, 0.8, 1.2, 1.6))
    assert anywhere.shape == (len(SPANS), 160)
    assert np.all(anywhere[:, _bins(0.5, 8.0)] == 1.0)
    floor = _profiles(depth, FLOOR)
    # a 0.2 m object on the floor shows its top (0.15 m) once 0.85 m / d < tan(vfov / 2), and
    # all of it (down to its lowest sample point, 0.05 m) once 0.95 m / d < tan(vfov / 2)
    half = math.tan(CAMERA.vfov / 2)
    top, whole = 0.85 / half, 0.95 / half
    assert np.all(floor[:, _bins(0.0, top - 0.1)] == 0.0)  # 0.5 m included
    partly = floor[CENTRE, _bins(top + 0.05, whole - 0.05)]
    assert np.all((partly > 0.0) & (partly < 1.0))  # its top shows, its foot does not
    assert np.all(floor[CENTRE, _bins(whole + 0.1, 8.0)] == 1.0)
    # outer columns look along longer rays, so their blind zone reaches further
    assert np.all(floor[:, _bins(whole / math.cos(CAMERA.hfov / 2) + 0.1, 8.0)] == 1.0)


def test_a_wall_hides_everything_behind_it() -> None:
    depth = _box_depth([(2.0, -5.0, 0.0, 2.2, 5.0, 3.0)])
    profiles = _profiles(depth, _levels(0.0, 0.4, 0.8, 1.2, 1.6))
    assert np.all(profiles[:, _bins(0.5, 1.9)] == 1.0)
    assert np.all(profiles[CENTRE, _bins(2.25, 8.0)] == 0.0)
    # the edge columns meet the wall 2 / cos(22.5 deg) = 2.16 m out
    assert np.all(profiles[:, _bins(2.4, 8.0)] == 0.0)


@pytest.mark.parametrize(
    ("level", "near", "far", "hidden"),
    [(0.0, 3.1, 3.5, True), (0.45, 2.1, 2.5, True), (1.2, 2.1, 4.0, False)],
)
def test_a_sofa_back_hides_the_floor_and_seats_behind_it_but_not_a_shelf(
    level: float, near: float, far: float, hidden: bool
) -> None:
    """A 0.8 m tall sofa back 1.5 m ahead; the levels behind it are in view without it."""
    supports = _levels(level)
    sofa = [(1.5, -3.0, 0.0, 1.7, 3.0, 0.8)]
    behind = _bins(near, far)
    assert np.all(_profiles(_box_depth([]), supports)[CENTRE, behind] == 1.0)
    with_sofa = _profiles(_box_depth(sofa), supports)[CENTRE, behind]
    assert np.all(with_sofa == (0.0 if hidden else 1.0))


def test_the_object_itself_does_not_hide_it() -> None:
    """The depth stops at the object's front face, 3.5 cm short of its centre: the tolerance
    counts that as the object seen; without one it would hide itself. (A box 0.4 m wide, so it
    fills every sampled pixel column of the middle patch column.)"""
    rice_box = [(3.465, -0.2, 0.0, 3.535, 0.2, 0.3)]
    depth = _box_depth(rice_box)
    at_box = _bins(3.45, 3.55)
    assert np.all(_profiles(depth, FLOOR, object_height=0.3)[CENTRE, at_box] == 1.0)
    assert np.all(_profiles(depth, FLOOR, object_height=0.3, tolerance=0.0)[9, at_box] == 0.0)
    # and a floor object well behind it, in the same columns, is hidden by it
    # and a floor object just behind it (its top seen over the box from 4 m on), is hidden
    assert np.all(_profiles(depth, FLOOR)[9, _bins(3.8, 3.95)] == 0.0)


def test_tilt_moves_the_blind_zone() -> None:
    level = _profiles(_box_depth([]), FLOOR)
    down = _profiles(_box_depth([], tilt=math.radians(-20)), FLOOR, tilt=math.radians(-20))
    up = _profiles(_box_depth([], tilt=math.radians(15)), FLOOR, tilt=math.radians(15))
    near, far = _bins(1.5, 2.0), _bins(6.0, 8.0)
    assert np.all(level[CENTRE, near] == 0.0) and np.all(level[CENTRE, far] == 1.0)
    assert np.all(down[CENTRE, near] == 1.0)  # looking down sees the floor at its feet
    assert np.all(up[CENTRE, far] == 0.0)  # looking up, the far floor drops out of the image


def test_profiles_are_fractions_of_the_sampled_pixel_columns() -> None:
    """A post covering the left half of a patch column hides what is behind it from half of
    the column's pixel columns."""
    u_mid = 160.0 + 16.0  # patch column 10 spans pixels 160..192; hide 160..176
    right_edge = math.tan(CAMERA.column_bearing(u_mid))  # lateral metres per metre ahead
    left_edge = math.tan(CAMERA.column_bearing(150.0))
    post = [(1.0, 1.0 * right_edge, 0.0, 1.05, 1.0 * left_edge, 3.0)]
    profiles = _profiles(_box_depth(post), _levels(1.0), samples=4)
    assert np.all(profiles[10, _bins(1.5, 4.0)] == 0.5)


def test_bad_inputs_are_named() -> None:
    depth = _box_depth([])
    with pytest.raises(InputError, match="depth image"):
        _profiles(depth[:, :100], FLOOR)
    with pytest.raises(InputError, match="reach"):
        _profiles(depth, FLOOR, reach=0.0)
    with pytest.raises(InputError, match="column_spans"):
        visibility_from_depth(
            depth,
            CAMERA,
            np.array([[10.0, 5.0]]),
            origin=(0.0, 0.0),
            axis=0.0,
            tilt=0.0,
            camera_height=1.0,
            supports=FLOOR,
            object_height=0.2,
            reach=4.0,
        )


# -- depth rendered in the twin ------------------------------------------------------------------
_WALL_SCENE = """
<mujoco>
  <visual><global offwidth="320" offheight="240"/></visual>
  <worldbody>
    <geom name="floor" type="plane" size="6 6 0.1"/>
    <geom name="wall" type="box" pos="3.1 0 0.6" size="0.1 4 0.6"/>
    <camera name="eye" pos="0 0 1" xyaxes="0 -1 0 0 0 1" fovy="{fovy}"/>
  </worldbody>
</mujoco>
"""


def test_rendered_depth_is_metres_along_each_ray_row_0_at_the_top() -> None:
    """A camera 3 m from a 1.2 m wall: every pixel meets the wall or the floor exactly where
    the pinhole puts it, and the sky above the wall (the top rows) is NaN."""
    model = mujoco.MjModel.from_xml_string(_WALL_SCENE.format(fovy=math.degrees(CAMERA.vfov)))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with FrameRenderer(model, CAMERA.width, CAMERA.height, "eye") as renderer:
        depth = renderer.depth(data)
        image = renderer.render(data)  # switching back to colour works
    assert image.shape == (240, 320, 3) and depth.shape == (240, 320)
    expected = _box_depth([(3.0, -4.0, 0.0, 3.2, 4.0, 1.2)])
    expected[expected > 50] = np.nan  # the box test scene's floor is endless; this one is not
    seen = np.isfinite(expected)
    assert np.array_equal(np.isnan(depth[seen]), np.zeros(seen.sum(), bool))
    interior = seen.copy()
    interior[93:96] = False  # the wall's top edge (0.2 m over the axis at 3 m: row 94.25)
    assert np.abs(depth[interior] - expected[interior]).max() < 0.02
    assert depth[120, 160] == pytest.approx(3.0 * math.hypot(1, 0.5 / CAMERA.focal_px), abs=0.01)
    assert np.all(np.isnan(depth[:93]))  # the top rows look over the wall
    assert np.all(np.isfinite(depth[96:]))


def test_sim_camera_frames_carry_depth_nearer_on_a_near_object() -> None:
    """The rice box 3 m ahead of the robot, its printed face towards it: the depth on its pixels
    puts that face 2.965 m ahead, and is less than on the floor beside it in the same rows."""
    sim, robot = make_sim_robot(start=Pose2D(2.25, 0.9, math.pi / 2))
    world = sim.world
    centre = sim.camera_position()[:2] + np.array([0.0, 3.0])
    world.place_static_body("rice_box", float(centre[0]), float(centre[1]), -math.pi / 2)
    robot.camera.connect()
    frame = robot.camera.grab()
    robot.camera.close()
    assert frame.depth is not None and frame.depth.shape == frame.image.shape[:2]
    with FrameRenderer(world.model, CAMERA.width, CAMERA.height, CAMERA_NAME) as renderer:
        ids = renderer.segment(world.data)
    box = ids == mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, "rice_box")
    assert box.sum() > 300
    rows, cols = np.nonzero(box)
    f = CAMERA.focal_px
    ahead = frame.depth[box] / np.sqrt(
        1 + ((cols + 0.5 - 160) / f) ** 2 + ((rows + 0.5 - 120) / f) ** 2
    )
    assert ahead.min() == pytest.approx(2.965, abs=0.01)  # the face (the top shows too)
    for row in np.unique(rows):
        mine = cols[rows == row]
        beside = frame.depth[row, mine.min() - 12 : mine.min() - 2]
        assert frame.depth[row, mine].max() < beside.min()

    plain = SimCamera(sim, CAMERA, depth=False)
    plain.connect()
    assert plain.grab().depth is None
    plain.close()


def test_model_depth_matches_the_twin_camera_where_robot_and_target_are_not_seen() -> None:
    """Looking at the rice box on the coffee table: the room model without robot and target
    renders the twin camera's depth, and sees past the box where the twin camera sees it."""
    sim, robot = make_sim_robot(start=Pose2D(2.3, 3.2, math.radians(120)))
    sim.move_head(math.radians(-8), math.radians(-10))
    world = sim.world
    robot.camera.connect()
    twin_depth = robot.camera.grab().depth
    robot.camera.close()
    assert twin_depth is not None
    # the localized pose of the optical centre and axis (here the truth)
    x, y, z = sim.camera_position()
    forward = -world.data.cam_xmat[sim.camera_id].reshape(3, 3)[:, 2]
    yaw, tilt = math.atan2(forward[1], forward[0]), math.asin(forward[2])
    with ModelDepth("living_room", CAMERA, world.targets()) as model:
        room = model.render(x, y, z, yaw, tilt)
    with FrameRenderer(world.model, CAMERA.width, CAMERA.height, CAMERA_NAME) as renderer:
        ids = renderer.segment(world.data)
    target = ids == mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, "rice_box")
    robot_geoms = np.nonzero(
        world.model.body_rootid[world.model.geom_bodyid] == world.body_id("base")
    )[0]
    assert target.sum() > 300  # the view does see the target, which the model leaves out
    # never nearer; deeper but where the box's foot meets the table top just behind it
    assert np.all(room[target] > twin_depth[target] - 0.01)
    assert np.mean(room[target] > twin_depth[target] + 0.05) > 0.8
    rest = ~target & ~np.isin(ids, robot_geoms)
    assert np.all(np.isfinite(room[rest]) == np.isfinite(twin_depth[rest]))
    close = np.abs(room[rest] - twin_depth[rest]) < 0.03
    assert close.mean() > 0.995  # all but silhouette edges


def test_model_depth_names_an_unknown_body() -> None:
    with pytest.raises(InputError, match="no body named 'teapot'"):
        ModelDepth("living_room", CAMERA, ["teapot"])


# -- depth from the laser map --------------------------------------------------------------------
def _map_with_block() -> OccupancyMap:
    """A 10 m square free map, 5 cm cells, origin at (-5, -5), with a block 2.0-2.2 m ahead of
    the origin and 1 m either side."""
    grid = np.zeros((200, 200))
    grid[80:120, 140:144] = 1.0  # y -1..1, x 2.0..2.2
    return OccupancyMap(grid, 0.05, (-5.0, -5.0, 0.0))


@pytest.mark.parametrize(("tilt_deg", "over"), [(0.0, True), (-15.0, False)])
def test_depth_from_map_sees_occupied_cells_as_walls(tilt_deg: float, over: bool) -> None:
    """Against exact ray casting of the block as a 1.2 m box: level, the top rows look over it;
    tilted down 15 degrees, none do."""
    tilt = math.radians(tilt_deg)
    depth = depth_from_map(
        _map_with_block(),
        CAMERA,
        origin=(0.0, 0.0),
        axis=0.0,
        tilt=tilt,
        camera_height=1.0,
        wall_height=1.2,
    )
    expected = _box_depth([(2.0, -1.0, 0.0, 2.2, 1.0, 1.2)], tilt=tilt)
    # the same pixels meet something (the top rows look over the block), at the same depths
    assert np.mean(np.isfinite(depth) == np.isfinite(expected)) > 0.995
    assert np.isnan(depth[0, 160]) == over and np.isfinite(depth[-1, 160])
    both = np.isfinite(expected) & np.isfinite(depth)
    assert np.quantile(np.abs(depth[both] - expected[both]), 0.99) < 0.02


def test_visibility_from_map_depth_hides_what_the_laser_map_blocks() -> None:
    depth = depth_from_map(
        _map_with_block(), CAMERA, origin=(0.0, 0.0), axis=0.0, tilt=0.0, camera_height=1.0
    )
    profiles = _profiles(depth, _levels(0.0, 0.45, 1.2))
    assert np.all(profiles[CENTRE, _bins(1.2, 1.9)] == 1.0)  # the 1.2 m shelf, wholly
    assert np.all(profiles[CENTRE, _bins(2.3, 8.0)] == 0.0)  # a 2 m wall hides every level


@pytest.mark.parametrize("lensed", [False, True])
def test_points_are_looked_up_where_the_lens_puts_them(lensed):
    """The depth lookup projects a point where the camera's own model says it lands: through a
    distorting lens (the twin's VC-C4) as through the ideal pinhole, and never a point from
    outside the field folded back in by the distortion polynomial."""
    from twin.core.visibility import project, projection_of
    from twin.sim.camera_effects import vcc4_lens

    camera = CameraModel.with_lens(320, 240, vcc4_lens()) if lensed else CameraModel()
    table = projection_of(camera)
    rng = np.random.default_rng(4)
    for _ in range(200):
        u, v = rng.uniform(0, 320), rng.uniform(0, 240)
        bearing, elevation = camera.pixel_rays(np.array(u), np.array(v))
        ahead = math.cos(float(elevation)) * math.cos(float(bearing))
        left = math.cos(float(elevation)) * math.sin(float(bearing))
        up = math.sin(float(elevation))
        col, row = project(-left / ahead, -up / ahead, table)
        assert (col, row) == pytest.approx((u, v), abs=1e-6)
    # a ray 80 degrees off the axis is outside a 47.5-degree field, whatever the polynomial says
    assert project(math.tan(math.radians(80)), 0.0, table) == (-1.0, -1.0)


def test_nothing_is_seen_past_a_wall_however_thin():
    """A column looking along +x at a 0.1 m wall 1.5 m away: the depth test alone lets a point
    stand 0.2 m behind the surface (the object's own half-width), which is past the wall's far
    face; past the wall's run of tall cells the profile is 0, before and inside it unchanged."""
    from twin.core.visibility import TallMap, block_behind

    tall = np.zeros((20, 40), bool)
    tall[:, 15] = True  # x 1.5-1.6 m
    walls = TallMap(0.0, -1.0, 0.1, tall)
    profiles = np.ones((2, 60))  # 0.05 m bins to 3 m
    blocked = block_behind(profiles, 0.05, (0.0, 0.0), np.array([0.0, math.pi]), walls)
    r = (np.arange(60) + 0.5) * 0.05
    assert (blocked[0, r < 1.6] == 1.0).all()  # up to and inside the wall
    assert (blocked[0, r > 1.6] == 0.0).all()  # past it
    assert (blocked[1] == 1.0).all()  # looking away


def test_the_apartment_walls_are_tall_and_a_wall_cabinet_is_not():
    from twin.sim.supports import tall_map
    from twin.sim.world import World

    walls = tall_map(World("apartment"))
    x = np.array([4.55, 4.65, 7.6, 9.65, 0.3])
    y = np.array([2.35, 2.35, 7.6, 7.65, 0.3])
    # the living room-bedroom wall; the bedroom beside it; the counter under the wall
    # cabinet; the fridge; the floor lamp
    assert walls.sample(x, y).tolist() == [True, False, False, True, False]
