"""The view log: a mission's views as numbers, fused again into any grid."""

from __future__ import annotations

import numpy as np
import pytest

from twin.app.view_log import LoggedView, ViewLog
from twin.core.errors import FileFormatError, InputError
from twin.core.fusion import make_rule
from twin.core.grid import AccumulatorGrid, GridSpec
from twin.core.visibility import ColumnVisibility

SPEC = GridSpec(0.0, 0.0, 4.0, 3.0, 0.1)


def _views(rng: np.random.Generator, n: int = 6, columns: int = 5) -> list[LoggedView]:
    out = []
    for i in range(n):
        origin = (float(rng.uniform(0.5, 3.5)), float(rng.uniform(0.5, 2.5)))
        axis = rng.uniform(-np.pi, np.pi)
        edges = axis + np.linspace(-0.35, 0.35, columns + 1)
        wedges = np.stack([edges[:-1], edges[1:]], axis=1)
        values = {"box": rng.uniform(0, 1, columns), "cup": rng.uniform(0, 1, columns)}
        # Every other view with a visibility model of its own reach.
        seen = None
        if i % 2:
            seen = ColumnVisibility(rng.uniform(0, 1, (columns, 20 + 10 * i)), 0.1)
        out.append(LoggedView(origin, wedges, values, seen, fused=i != 3))
    return out


def _mission_grid(views: list[LoggedView], rule_name: str = "accumulate") -> AccumulatorGrid:
    grid = AccumulatorGrid(["box", "cup"], SPEC, make_rule(rule_name), 4)
    for view in views:
        if view.fused:
            grid.fuse_all(view.origin, view.wedges, view.values, 3.0, view.visibility)
    return grid


def test_replaying_a_saved_log_gives_the_missions_grid_exactly(tmp_path) -> None:
    views = _views(np.random.default_rng(3))
    log = ViewLog(["box", "cup"], 3.0)
    for view in views:
        log.append(view)
    log.save(tmp_path / "views.npz")
    loaded = ViewLog.load(tmp_path / "views.npz")
    assert len(loaded) == len(views)
    replayed = loaded.fuse_into(AccumulatorGrid(["box", "cup"], SPEC, make_rule("accumulate"), 4))
    expected = _mission_grid(views)
    for name in ("box", "cup"):
        np.testing.assert_array_equal(replayed.evidence(name), expected.evidence(name))
        np.testing.assert_array_equal(replayed.observed(name), expected.observed(name))
        assert replayed.views(name) == expected.views(name) == 5  # the refused view is skipped


def test_without_visibility_the_replay_is_the_papers_fusion() -> None:
    views = _views(np.random.default_rng(4))
    log = ViewLog(["box", "cup"], 3.0)
    for view in views:
        log.append(view)
    blind = log.fuse_into(
        AccumulatorGrid(["box", "cup"], SPEC, make_rule("normalized"), 4), visibility=False
    )
    expected = _mission_grid(
        [LoggedView(v.origin, v.wedges, v.values, None, v.fused) for v in views]
    )
    np.testing.assert_array_equal(blind.observed("box"), expected.observed("box"))
    seeing = log.fuse_into(AccumulatorGrid(["box", "cup"], SPEC, make_rule("normalized"), 4))
    assert seeing.observed("box").sum() < blind.observed("box").sum()


def test_the_first_views_only_and_truncation() -> None:
    views = _views(np.random.default_rng(5))
    log = ViewLog(["box", "cup"], 3.0)
    for view in views:
        log.append(view)
    first = log.fuse_into(
        AccumulatorGrid(["box", "cup"], SPEC, make_rule("accumulate"), 4), views=2
    )
    log.truncate(2)
    assert len(log) == 2
    again = log.fuse_into(AccumulatorGrid(["box", "cup"], SPEC, make_rule("accumulate"), 4))
    np.testing.assert_array_equal(first.evidence("cup"), again.evidence("cup"))


def test_a_view_must_name_every_object_and_share_the_column_count() -> None:
    views = _views(np.random.default_rng(6))
    log = ViewLog(["box", "cup"], None)
    log.append(views[0])
    with pytest.raises(InputError, match="values for"):
        log.append(LoggedView((1, 1), views[1].wedges, {"box": views[1].values["box"]}, None))
    with pytest.raises(InputError, match="columns"):
        log.append(LoggedView((1, 1), views[1].wedges[:3], views[1].values, None))


def test_a_damaged_log_is_a_one_line_error(tmp_path) -> None:
    path = tmp_path / "views.npz"
    path.write_bytes(b"not a zip file")
    with pytest.raises(FileFormatError):
        ViewLog.load(path)


def test_a_view_taken_for_some_objects_only_is_fused_into_theirs(tmp_path) -> None:
    """The floor sweep's views are for the floor's objects: NaN values for the others leave
    their layers and view counts untouched, live and replayed from the saved log."""
    views = _views(np.random.default_rng(7), n=4)
    for_box = [
        LoggedView(v.origin, v.wedges, {**v.values, "cup": np.full(len(v.wedges), np.nan)},
                   v.visibility)
        for v in views
    ]  # fmt: skip
    log = ViewLog(["box", "cup"], 3.0)
    for view in for_box:
        log.append(view)
    log.save(tmp_path / "views.npz")
    replayed = ViewLog.load(tmp_path / "views.npz").fuse_into(
        AccumulatorGrid(["box", "cup"], SPEC, make_rule("accumulate"), 4)
    )
    assert replayed.views("box") == 4 and replayed.views("cup") == 0
    assert not replayed.evidence("cup").any()
    only_box = AccumulatorGrid(["box"], SPEC, make_rule("accumulate"), 4)
    for view in views:
        only_box.fuse_all(view.origin, view.wedges, {"box": view.values["box"]}, 3.0,
                          view.visibility)  # fmt: skip
    np.testing.assert_array_equal(replayed.evidence("box"), only_box.evidence("box"))
