"""twin/ObjectSearch-v0 (twin.envs): gymnasium's own checker, seeding, budgets, invalid actions."""

from __future__ import annotations

import importlib
import sys
import warnings

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")

import twin.envs  # noqa: E402 - registers the environment
from twin.core.errors import InputError  # noqa: E402
from twin.envs.object_search import FOUND_BONUS, INVALID_PENALTY, ObjectSearchEnv  # noqa: E402

# A small search: 15 places x 8 headings, at most 4 steps an episode.
SMALL = ("search.max_views=4", "search.spacing_m=0.8", "run.rerun=off")


def small(cache) -> tuple[str, ...]:
    return (*SMALL, f"run.cache={cache}")


@pytest.fixture(scope="module")
def env(model_cache):
    made = gymnasium.make(twin.envs.OBJECT_SEARCH, overrides=small(model_cache))
    yield made
    made.close()


def placement(info: dict) -> dict:
    return {name: entry["truth_m"] for name, entry in info["objects"].items()}


def test_gymnasium_make_gives_the_environment_after_import(env):
    assert env.spec.id == "twin/ObjectSearch-v0"
    assert isinstance(env.unwrapped, ObjectSearchEnv)
    candidates = env.unwrapped.candidates
    assert env.action_space.n == candidates.n_views == len(candidates.places) * 8
    assert len(candidates.places) >= 4  # the tests below take views at several places
    assert set(env.observation_space.spaces) == {"scores", "pose", "grid", "taken"}


def test_gymnasiums_env_checker_passes(env):
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)  # also makes it again in "rgb_array" mode and closes it twice
    assert [str(w.message) for w in caught] == []


def test_the_same_seed_gives_the_same_episode_start_and_another_seed_another(env):
    first, info_1 = env.reset(seed=11)
    again, info_2 = env.reset(seed=11)
    assert placement(info_1) == placement(info_2)
    for key in first:
        np.testing.assert_array_equal(first[key], again[key])
    _, other = env.reset(seed=12)
    assert placement(other) != placement(info_1)
    assert np.all(first["scores"] == 0.0) and first["taken"].sum() == 0
    assert first["grid"].sum() == pytest.approx(1.0 - 0.1, abs=1e-4)  # the prior p_absent


def test_a_fixed_action_sequence_ends_within_the_budget(env):
    _, info = env.reset(seed=21)
    n = env.action_space.n
    # more actions than the budget: the episode must end before they run out
    actions = [0, n // 3, (2 * n) // 3, n - 1, 3, n // 2]
    steps, total, ended = 0, 0.0, False
    for action in actions:
        time_before = info["robot_time_s"]
        obs, reward, terminated, truncated, info = env.step(action)
        steps += 1
        assert obs in env.observation_space
        spent = (info["robot_time_s"] - time_before) / 60.0
        bonus = FOUND_BONUS * len(info.get("found", []))
        assert reward == pytest.approx(
            -spent + bonus - INVALID_PENALTY * (info["invalid"] is not None), abs=1e-4
        )
        total += reward
        if terminated or truncated:
            ended = True
            break
    assert ended and steps <= 4
    assert info["steps"] == steps == info["views"] + info["invalid_actions"]
    assert info["stopped"]
    assert info["path_length_m"] >= 0.0 and info["robot_time_s"] > 0.0
    entry = info["objects"]["rice_box"]
    assert entry["error_m"] >= 0.0 and 0.0 <= entry["confidence"] <= 1.0


def test_an_invalid_action_is_penalised_and_not_taken(env):
    env.reset(seed=31)
    view = 50
    obs, reward, terminated, _, info = env.step(view)
    assert info["invalid"] is None and not terminated  # one view is not enough to be sure
    assert obs["taken"][view] == 1 and obs["taken"].sum() == 1
    assert info["action_mask"][view] == 0
    again, reward, _, _, after = env.step(view)
    assert after["invalid"] == "taken" and reward == pytest.approx(-INVALID_PENALTY)
    assert after["views"] == info["views"] == 1 and after["invalid_actions"] == 1
    assert after["robot_time_s"] == info["robot_time_s"]
    np.testing.assert_array_equal(again["scores"], obs["scores"])
    np.testing.assert_array_equal(again["taken"], obs["taken"])
    with pytest.raises(InputError, match="view index"):
        env.step(env.action_space.n)


def test_an_unreachable_view_is_penalised_and_not_taken(env, monkeypatch):
    env.reset(seed=32)
    search = env.unwrapped
    _, _, _, _, info = env.step(8)  # place 1 (8 headings a place), reachable from the start
    # From here on the map says no place can be driven to: only turning on the spot is left.
    nowhere = np.full(len(search.candidates.places), np.inf)
    monkeypatch.setattr(search.searcher, "place_metres", lambda here: nowhere)
    obs, _, _, _, info = env.step(9)  # place 1 again, another heading: a turn, no drive
    assert info["invalid"] is None and info["views"] == 2
    far = env.action_space.n - 1  # the last place's last heading
    assert info["action_mask"][far] == 0 and info["action_mask"].sum() > 0
    again, reward, _, _, after = env.step(far)
    assert after["invalid"] == "unreachable" and reward == pytest.approx(-INVALID_PENALTY)
    assert after["views"] == 2 and after["robot_time_s"] == info["robot_time_s"]
    np.testing.assert_array_equal(again["taken"], obs["taken"])


def test_a_place_the_base_refuses_is_struck_off_and_refusals_in_a_row_end_it(env, monkeypatch):
    """As a search does: a refused drive is penalised and its place struck off; MAX_REFUSALS
    refusals in a row end the episode (batch-survey counts such a run failed)."""
    from twin.app.search import MAX_REFUSALS
    from twin.core.devices import DeviceFaultError

    env.reset(seed=33)
    base = env.unwrapped.mission.robot.base

    def refuses(goal, **_):
        raise DeviceFaultError(base.name, "go to", "touched the sofa", "clear the way")

    monkeypatch.setattr(base, "go_to", refuses)
    places = env.unwrapped.candidates.places
    for k in range(MAX_REFUSALS):
        view = (k + 1) * 8  # a heading at places 1, 2, 3
        _, reward, terminated, truncated, info = env.step(view)
        assert info["invalid"].startswith("drive failed") and info["views"] == 0
        assert reward == pytest.approx(-INVALID_PENALTY)
        if k + 1 < MAX_REFUSALS:
            assert not (terminated or truncated)
            assert not info["action_mask"][view : view + 8].any()  # the place is struck off
            assert info["unreachable"][-1]["place_m"] == list(places[k + 1])
    assert truncated and not terminated and "touched the sofa" in info["stopped"]
    assert info["stopped"].startswith("the robot could not go on")
    with pytest.raises(InputError, match="reset"):
        env.step(0)


def test_the_config_planners_episode_is_batch_surveys_search_run(env, model_cache):
    """An episode is a mission in a reset world: flown by the config's own planner, it is the
    run of ``twin batch-survey --mission search`` with the episode's draw, view for view."""
    from twin.app.batch import BatchSpec, run_batch_mission

    _, info = env.reset(seed=51)
    search, done = env.unwrapped, False
    while not done:
        action = search.searcher.planner.choose(search.situation).index
        _, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
    spec = BatchSpec.from_config(None, small(model_cache), vary=("target",), mission="search")
    run = run_batch_mission(spec, info["draw"])
    assert run["views"] == info["views"] and run["time_s"] == info["robot_time_s"]
    assert run["path_length_m"] == info["path_length_m"]
    mine = info["objects"]["rice_box"]
    assert run["objects"]["rice_box"]["truth_m"] == mine["truth_m"]
    assert run["objects"]["rice_box"]["error_m"] == mine["error_m"]


def test_image_observations_and_rendering_show_the_last_frame(model_cache):
    made = gymnasium.make(
        twin.envs.OBJECT_SEARCH,
        overrides=small(model_cache),
        observation="image",
        render_mode="rgb_array",
    )
    try:
        obs, _ = made.reset(seed=41)
        assert obs["image"].shape == (240, 320, 3) and obs["image"].dtype == np.uint8
        assert not obs["image"].any() and not made.render().any()  # nothing seen yet
        obs, *_ = made.step(int(np.argmax(made.unwrapped.action_mask())))
        assert obs in made.observation_space and obs["image"].any()
        np.testing.assert_array_equal(made.render(), obs["image"])
    finally:
        made.close()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"observation": "pixels"}, "observation must be one of"),
        ({"render_mode": "human"}, "render_mode"),
        ({"vary": ("lighting",)}, 'vary must include "target"'),
        ({"overrides": "search.max_views=4"}, "tuple"),
        ({"max_views": 0}, "max_views must be a positive integer"),
    ],
)
def test_bad_options_are_one_line(kwargs, match):
    with pytest.raises(InputError, match=match) as caught:
        ObjectSearchEnv(**kwargs)
    assert "\n" not in str(caught.value)


def test_without_gymnasium_the_import_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "gymnasium", None)  # "import gymnasium" now fails
    monkeypatch.delitem(sys.modules, "twin.envs")
    with pytest.raises(ImportError, match=r"pip install 'bearing-twin\[gym\]'"):
        importlib.import_module("twin.envs")
