"""Step 8's speed figures in one run: a simulated scan, an MCL update, and the default survey on
the laser beside the same survey on odometry.

    python benchmarks/bench_localization.py [--repeats 2]

* one 361-beam (and one 181-beam) scan of the MuJoCo LMS200 in the living room (goal <= 1 ms);
* one Monte Carlo update with 500 particles weighing 181 beams of a real scan of the twin, on
  the living room's map cut at 0.30 m (goal <= 5 ms), and the default's 500 x 60;
* the default survey (``twin survey``, the shipped config, model cache warm) from command start
  to result with ``robot.base.pose_source`` = ``odometry`` and = ``laser``, alternating, best of
  ``--repeats`` each (goal: the laser's at most 1.5 x the odometry's).
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np


def best_ms(fn, repeats: int = 200) -> float:
    fn()  # compile / warm up
    times = []
    for _ in range(repeats):
        tick = time.perf_counter()
        fn()
        times.append(time.perf_counter() - tick)
    return 1000.0 * float(np.median(times))


def scan_and_update_figures() -> None:
    from twin.core.geometry import Pose2D
    from twin.nav.mcl import MclConfig, MonteCarloLocalizer
    from twin.sim import make_sim_robot
    from twin.sim.laser import LaserSpec, RayCaster, SimLaser
    from twin.sim.scene_map import scene_map

    start = Pose2D(2.25, 2.5, math.radians(90.0))
    sim, _ = make_sim_robot("living_room", start=start)
    for beams in (361, 181):
        spec = LaserSpec(beams=beams)
        laser = SimLaser(sim, spec)
        caster = RayCaster(sim.world.model, laser.site, spec.angles, spec.max_range)
        ms = best_ms(lambda caster=caster: caster.cast(sim.world.data))
        print(f"one simulated {beams}-beam scan (mj_multiRay): {ms:.3f} ms (goal <= 1 ms)")
    laser = SimLaser(sim, LaserSpec(beams=181))
    laser.connect()
    scan = laser.scan()
    occupancy = scene_map(sim.world, laser.mount.z, 0.05)
    for particles, beams in ((500, 181), (500, 60)):
        mcl = MonteCarloLocalizer(
            occupancy,
            laser.mount,
            rng=np.random.default_rng(0),
            particles=particles,
            config=MclConfig(beams=beams),
            initial_pose=start,
        )
        odometry = sim.odometry_pose()
        ms = best_ms(lambda mcl=mcl, odometry=odometry: mcl.update(odometry, scan), repeats=100)
        goal = " (goal <= 5 ms)" if beams == 181 else ""
        print(f"one MCL update, {particles} particles x {beams} beams: {ms:.2f} ms{goal}")
    laser.close()


def survey_seconds(folder: Path, source: str, k: int) -> float:
    out = folder / f"{source}-{k}"
    argv = [sys.executable, "-m", "twin.cli", "survey", "--out", str(out), "--quiet",
            "--set", "run.rerun=off", "--set", f"robot.base.pose_source={source}"]  # fmt: skip
    tick = time.perf_counter()
    subprocess.run(argv, check=True)
    return time.perf_counter() - tick


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    scan_and_update_figures()
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        survey_seconds(folder, "odometry", -1)  # train and cache the detector first
        times: dict[str, list[float]] = {"odometry": [], "laser": []}
        for k in range(args.repeats):
            for source in times:
                times[source].append(survey_seconds(folder, source, k))
    odometry, laser = min(times["odometry"]), min(times["laser"])
    print(
        f"default survey, command start to result: odometry {odometry:.1f} s, laser "
        f"{laser:.1f} s = {laser / odometry:.2f} x (goal <= 1.5 x; best of {args.repeats})"
    )


if __name__ == "__main__":
    main()
