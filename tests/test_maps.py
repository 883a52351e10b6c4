"""Occupancy maps in the ROS map_server format: round trips, files as slam_toolbox and map_server
write them, and bad files as one-line errors naming the file."""

import numpy as np
import pytest

from twin.core.errors import FileFormatError, InputError
from twin.nav.maps import UNKNOWN, OccupancyMap, load_map, read_pgm, save_map

# As ROS's map_saver (the one slam_toolbox's "save map" calls) writes it.
MAP_SERVER_YAML = """image: map.pgm
resolution: 0.050000
origin: [-10.000000, -10.000000, 0.000000]
negate: 0
occupied_thresh: 0.65
free_thresh: 0.196

"""
# 4 wide, 3 high; image row 0 is the map's top. 254 free, 0 occupied, 205 unknown.
MAP_SERVER_PIXELS = np.array(
    [
        [0, 0, 0, 205],
        [0, 254, 254, 205],
        [0, 254, 254, 254],
    ],
    dtype=np.uint8,
)


def write_map_server_files(folder, yaml=MAP_SERVER_YAML, pixels=MAP_SERVER_PIXELS):
    height, width = pixels.shape
    header = f"P5\n# CREATOR: map_saver.cpp 0.050 m/pix\n{width} {height}\n255\n".encode()
    (folder / "map.pgm").write_bytes(header + pixels.tobytes())
    (folder / "map.yaml").write_text(yaml)
    return folder / "map.yaml"


def test_a_map_server_file_loads_with_row_0_at_the_bottom(tmp_path):
    loaded = load_map(write_map_server_files(tmp_path))
    assert loaded.shape == (3, 4)
    assert loaded.resolution == 0.05
    assert loaded.origin == (-10.0, -10.0, 0.0)
    assert (loaded.occupied_thresh, loaded.free_thresh) == (0.65, 0.196)
    # the image's top row is the map's highest row
    expected = np.array(
        [
            [1.0, 0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, UNKNOWN],
            [1.0, 1.0, 1.0, UNKNOWN],
        ]
    )
    np.testing.assert_array_equal(loaded.occupancy, expected)
    # the top-right pixel is unknown and sits at the map's largest x and y
    row, col = loaded.cell_of(-10.0 + 3.5 * 0.05, -10.0 + 2.5 * 0.05)
    assert (row, col) == (2, 3) and loaded.unknown[row, col]
    assert loaded.extent == pytest.approx((-10.0, -10.0, -9.8, -9.85))


def test_plain_pgm_and_nav2_style_yaml_read_the_same(tmp_path):
    binary = load_map(write_map_server_files(tmp_path))
    plain = tmp_path / "plain"
    plain.mkdir()
    rows = "\n".join(" ".join(str(v) for v in row) for row in MAP_SERVER_PIXELS)
    (plain / "map.pgm").write_text(f"P2\n# a comment\n4 3\n# another\n255\n{rows}\n")
    # nav2's map_saver: mode given, fewer decimals, a comment, the origin as a block list
    (plain / "map.yaml").write_text(
        "# saved by hand\nimage: 'map.pgm'\nmode: trinary\nresolution: 0.050  # m/pixel\n"
        "origin:\n  - -10.000\n  - -10.000\n  - 0\nnegate: 0\noccupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    )
    loaded = load_map(plain / "map.yaml")
    np.testing.assert_array_equal(loaded.occupancy, binary.occupancy)
    assert loaded.origin == binary.origin and loaded.resolution == binary.resolution


def test_scale_mode_and_negate_follow_map_server(tmp_path):
    pixels = np.array([[0, 100, 200, 255]], dtype=np.uint8)
    yaml = MAP_SERVER_YAML.replace("negate: 0", "negate: 1") + "mode: scale\n"
    loaded = load_map(write_map_server_files(tmp_path, yaml, pixels))
    # negate: a white pixel is occupied; scale keeps the occupancy itself
    np.testing.assert_allclose(loaded.occupancy[0], [0.0, 100 / 255, 200 / 255, 1.0])
    np.testing.assert_array_equal(loaded.occupied[0], [False, False, True, True])
    np.testing.assert_array_equal(loaded.free[0], [True, False, False, False])


def test_raw_mode_reads_percentages(tmp_path):
    pixels = np.array([[0, 65, 100, 255]], dtype=np.uint8)
    loaded = load_map(write_map_server_files(tmp_path, MAP_SERVER_YAML + "mode: raw\n", pixels))
    np.testing.assert_allclose(loaded.occupancy[0], [0.0, 0.65, 1.0, UNKNOWN])


def test_save_then_load_keeps_every_cell_class_and_the_geometry(tmp_path):
    rng = np.random.default_rng(3)
    occupancy = rng.uniform(0.0, 1.0, size=(37, 52))
    occupancy[rng.uniform(size=occupancy.shape) < 0.2] = UNKNOWN
    original = OccupancyMap(occupancy, 0.05, (-1.25, 0.5, 0.0))
    path = save_map(original, tmp_path / "room" / "map.yaml")
    assert path == tmp_path / "room" / "map.yaml"
    assert sorted(p.name for p in path.parent.iterdir()) == ["map.pgm", "map.yaml"]
    loaded = load_map(path)
    assert loaded.shape == original.shape
    assert loaded.origin == original.origin and loaded.resolution == original.resolution
    np.testing.assert_array_equal(loaded.occupied, original.occupied)
    np.testing.assert_array_equal(loaded.free, original.free)
    np.testing.assert_array_equal(loaded.unknown, original.unknown)


def test_saved_image_is_map_servers_trinary_pgm_with_row_0_at_the_top(tmp_path):
    occupancy = np.zeros((3, 5))
    occupancy[2, 0] = 1.0  # the top-left corner of the map (largest y, smallest x)
    occupancy[0, 4] = UNKNOWN  # the bottom-right
    path = save_map(OccupancyMap(occupancy, 0.1, (2.0, -3.0, 0.0)), tmp_path / "m.yaml")
    pixels, maxval = read_pgm(tmp_path / "m.pgm")
    assert maxval == 255 and (tmp_path / "m.pgm").read_bytes()[:2] == b"P5"
    expected = np.full((3, 5), 254)
    expected[0, 0] = 0
    expected[2, 4] = 205
    np.testing.assert_array_equal(pixels, expected)
    text = path.read_text()
    assert "image: m.pgm\n" in text and "origin: [2.0, -3.0, 0.0]\n" in text
    assert "mode: trinary\n" in text and "negate: 0\n" in text


def test_thresholds_other_than_map_savers_still_round_trip(tmp_path):
    occupancy = np.array([[0.0, 1.0, UNKNOWN, 0.5]])
    original = OccupancyMap(occupancy, 0.05, occupied_thresh=0.8, free_thresh=0.3)
    loaded = load_map(save_map(original, tmp_path / "m.yaml"))
    assert (loaded.occupied_thresh, loaded.free_thresh) == (0.8, 0.3)
    np.testing.assert_array_equal(loaded.unknown, [[False, False, True, True]])
    np.testing.assert_array_equal(loaded.occupied, original.occupied)


def test_saving_to_the_image_name_is_refused(tmp_path):
    with pytest.raises(InputError, match="YAML"):
        save_map(OccupancyMap(np.zeros((2, 2)), 0.05), tmp_path / "m.pgm")


GOOD_PGM = b"P5\n2 1\n255\n\x00\xfe"


@pytest.mark.parametrize(
    ("yaml", "image", "message"),
    [
        (None, GOOD_PGM, "no such map file"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", None, "image does not exist"),
        ("image: map.pgm\norigin: [0, 0, 0]\n", GOOD_PGM, "has no 'resolution'"),
        ("image: map.pgm\nresolution: fine\norigin: [0, 0, 0]\n", GOOD_PGM, "must be a number"),
        ("image: map.pgm\nresolution: -0.05\norigin: [0, 0, 0]\n", GOOD_PGM, "positive"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0]\n", GOOD_PGM, r"\[x, y, yaw\]"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0.5]\n", GOOD_PGM, "rotated"),
        ("resolution: 0.05\norigin: [0, 0, 0]\n", GOOD_PGM, "'image'"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nmode: fancy\n", GOOD_PGM, "mode"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 2\n", GOOD_PGM, "negate"),
        (
            "image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nfree_thresh: 0.9\n",
            GOOD_PGM,
            "thresholds",
        ),
        ("image: map.pgm\nresolution: 0.05\nresolution: 0.1\n", GOOD_PGM, "line 3.*twice"),
        ("image: map.pgm\nmap:\n  resolution: 0.05\n", GOOD_PGM, "line 3.*flat"),
        ("image: map.pgm\norigin: [0, 0, 0\n", GOOD_PGM, "not closed"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"\x89PNG\r\n\x1a\n", "PNG"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P5\n2 1\n255\n\x00", "trunc"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P5\n2 x\n255\n", "number"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P5\n2 1\n", "ends early"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P2\n2 1\n9\n3 10\n", "maxval"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P5\n0 1\n255\n", "range"),
    ],
)
def test_a_bad_map_is_one_line_naming_the_file(tmp_path, yaml, image, message):
    if yaml is not None:
        (tmp_path / "map.yaml").write_text(yaml)
    if image is not None:
        (tmp_path / "map.pgm").write_bytes(image)
    with pytest.raises(FileFormatError, match=message) as caught:
        load_map(tmp_path / "map.yaml")
    text = str(caught.value)
    assert "\n" not in text
    assert "map.yaml" in text or "map.pgm" in text
