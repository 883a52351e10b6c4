"""Where visibility changed the decision: the frame, its depth, what it hid, both grids.

    python benchmarks/visibility_frames.py runs/report/seed-5003 --out docs/visibility-5003.png

Takes a run flown by ``benchmarks/fusion_generality.py`` (``--place-target random``), fuses its
view log with ``--rule`` (default: the shipped config's) twice, blind and with the visibility
model (and, for the shipped rule, the room's baseline that visibility makes possible), and,
when the two decisions differ, draws the view whose visibility changed the true cell's
evidence most: its frame and depth re-rendered in the twin at the view's pose (the
run's placement is re-made from its seed), the cells of that view the depth hid, and the two
final grids with the truth and both estimates. Prints the two errors either way.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a run folder with views.npz and result.json")
    parser.add_argument("--out", type=Path, help="PNG to write (only when the decision differs)")
    parser.add_argument("--rule", help="fusion rule (default: the shipped config's grid)")
    args = parser.parse_args()

    from twin.app.config import load_config
    from twin.app.detection import mission_detector
    from twin.app.run import make_grids
    from twin.app.view_log import ViewLog
    from twin.core.fusion import make_rule
    from twin.core.grid import AccumulatorGrid

    # The run's own config for the scene and detector; the rule and its direction bins are the
    # shipped default's (the runs may have been flown under another), or --rule without bins.
    config = load_config(args.run / "config.toml")
    detector, rooms = mission_detector(config, lambda _: None)
    name = config.objects[0].name
    grid, _ = make_grids(load_config(None), detector, rooms)
    rule = grid.rules if args.rule is None else make_rule(args.rule)
    bins = grid.direction_bins if args.rule is None else 1
    # With visibility, the default also takes the room's look off (a blind grid cannot: the
    # baseline is per share of a cell seen), so "blind" is the rule as the paper fuses it.
    baseline = grid.baselines if args.rule is None else None
    log = ViewLog.load(args.run / "views.npz")
    result = json.loads((args.run / "result.json").read_text())
    truth = tuple(result["objects"][name]["truth_m"])
    spec = config.grid.spec

    def fused(visibility: bool, views: int | None = None) -> AccumulatorGrid:
        grid = AccumulatorGrid([name], spec, rule, config.grid.supersample, direction_bins=bins,
                               baseline=baseline if visibility else None)  # fmt: skip
        return log.fuse_into(grid, visibility=visibility, views=views)

    blind, seeing = fused(False), fused(True)
    estimates = {}
    for label, grid in (("blind", blind), ("with visibility", seeing)):
        best = grid.peaks(name, k=1, min_separation=config.grid.peak_separation).best
        estimates[label] = (best.x, best.y)
        print(f"{label}: estimate ({best.x:.2f}, {best.y:.2f}), error "
              f"{math.dist((best.x, best.y), truth):.2f} m")  # fmt: skip
    if args.out is None:
        return

    def cell_of(xy: tuple[float, float]) -> tuple[int, int]:
        return int((xy[1] - spec.y_min) / spec.cell_size), int(
            (xy[0] - spec.x_min) / spec.cell_size
        )

    # The view whose visibility most changed the true cell's standing against the wrong
    # estimate's cell: the margin (true minus rival) it adds with visibility, less blind. When
    # visibility helped, the rival is the blind estimate and the largest gain is drawn; when it
    # hurt, the rival is its own estimate and the largest loss.
    errors = {label: math.dist(xy, truth) for label, xy in estimates.items()}
    helped = errors["with visibility"] <= errors["blind"]
    true_cell = cell_of(truth)
    rival = cell_of(estimates["blind" if helped else "with visibility"])
    change = []
    for i in range(len(log)):
        margins = []
        for visibility in (True, False):
            before, after = fused(visibility, i).layer(name), fused(visibility, i + 1).layer(name)
            step = after - before
            margins.append(step[true_cell] - step[rival])
        change.append(margins[0] - margins[1])
    index = int(np.argmax(change) if helped else np.argmin(change))
    view = log.views[index]
    against = "the blind estimate's" if helped else "its own estimate's"
    print(f"view {index}: with visibility the true cell gains {change[index]:+.2f} more on "
          f"{against} cell than blind")  # fmt: skip
    image, depth = render_view(args.run, view, name)
    title = (f"view {index}: with visibility the true cell (red ring) gains {change[index]:+.2f}"
             f" more on {against} cell (white squares: the estimates) than blind")  # fmt: skip
    draw(args.out, view, image, depth, blind.layer(name), seeing.layer(name), spec, truth,
         estimates, index, title, config)  # fmt: skip
    print(f"wrote {args.out}")


def render_view(run: Path, view, name: str) -> tuple[np.ndarray, np.ndarray]:
    """The view's frame and depth, re-rendered: the run's placement re-made from its seed, the
    robot at the view's camera position facing its optical axis."""
    from twin.core.geometry import Pose2D
    from twin.sim.placement import random_surface_pose
    from twin.sim.robot import make_sim_robot

    options = json.loads((run / "run.json").read_text())
    sim, robot = make_sim_robot()
    random_surface_pose(sim.world, name, np.random.default_rng(options["seed"]))
    axis = float(np.mean(view.wedges))
    sim.place(Pose2D(view.origin[0], view.origin[1], axis), settle=0.0)
    robot.camera.connect()
    frame = robot.camera.grab()
    robot.camera.close()
    return frame.image, frame.depth


def draw(out, view, image, depth, blind, seeing, spec, truth, estimates, index, title, config):
    from matplotlib.colors import ListedColormap

    from twin.app.plots import _pyplot, save_figure
    from twin.sim import World

    plt = _pyplot()
    world = World(config.scene)
    extent = (spec.x_min, spec.x_max, spec.y_min, spec.y_max)
    ratios = {"width_ratios": [1.33, 1.33, 0.75, 0.75, 0.75]}
    fig, axes = plt.subplots(1, 5, figsize=(22, 5), layout="constrained", gridspec_kw=ratios)
    axes[0].imshow(image)
    axes[0].set_title(f"view {index}: the frame")
    shown = axes[1].imshow(depth, cmap="turbo")
    fig.colorbar(shown, ax=axes[1], label="depth along the ray (m)", shrink=0.8)
    axes[1].set_title("its depth (rendered with the frame)")
    # What this view's columns could see: the visibility at each cell centre in its wedges.
    xs, ys = spec.cell_centers()
    seen = np.full(spec.shape, np.nan)
    bearing = np.arctan2(ys - view.origin[1], xs - view.origin[0])
    distance = np.hypot(xs - view.origin[0], ys - view.origin[1])
    bins = (distance / view.visibility.step).astype(int)
    for c, (a0, a1) in enumerate(view.wedges):
        inside = ((bearing - a0) % (2 * math.pi)) < (a1 - a0)
        inside &= bins < view.visibility.profiles.shape[1]
        seen[inside] = view.visibility.profiles[c, bins[inside]]
    axes[2].imshow(seen, origin="lower", extent=extent, cmap=ListedColormap(
        plt.cm.RdYlGn(np.linspace(0, 1, 11))), vmin=0, vmax=1)  # fmt: skip
    axes[2].set_title("what it could see (green) and not (red)")
    for ax, layer, label in ((axes[3], blind, "blind"), (axes[4], seeing, "with visibility")):
        ax.imshow(layer, origin="lower", extent=extent, cmap="viridis")
        x, y = estimates[label]
        ax.plot([x], [y], "ws", markersize=10, fillstyle="none", markeredgewidth=2)
        ax.set_title(f"{label}: error {math.dist((x, y), truth):.2f} m")
    for ax in axes[2:]:
        for footprint in (world.footprint(n) for n in world.furniture()):
            polygon = np.vstack([footprint.polygon, footprint.polygon[:1]])
            ax.plot(polygon[:, 0], polygon[:, 1], color="white", linewidth=0.6)
        ax.plot([truth[0]], [truth[1]], "o", color="red", markersize=12, fillstyle="none")
        ax.plot([view.origin[0]], [view.origin[1]], "^", color="cyan")
        ax.set_xlim(spec.x_min, spec.x_max)
        ax.set_ylim(spec.y_min, spec.y_max)
    fig.suptitle(title)
    save_figure(fig, out, tight=False)


if __name__ == "__main__":
    main()
