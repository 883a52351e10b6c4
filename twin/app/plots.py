"""Figures, drawn headless with matplotlib's Agg backend and written atomically as PNG."""

from __future__ import annotations

import io
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from twin.core.geometry import is_wall
from twin.core.store import write_atomic

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: Path, dpi: int = 110, tight: bool = True) -> Path:
    """Render ``fig`` to PNG bytes, then write them atomically; the figure is closed.

    ``tight`` crops the margins, at the cost of drawing the figure twice; a figure laid out
    with ``layout="constrained"`` has no margins to crop and is drawn once without it.
    """
    plt = _pyplot()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight" if tight else None)
    plt.close(fig)
    return write_atomic(path, lambda handle: handle.write(buffer.getvalue()))


SUCCESS_CMAP = "viridis"
# Heat-map cells are at least this many inches a side, so a "100" fits in a legible font.
_CELL_INCHES = 0.36
# The 3-D panels' view: from the (P_fp, P_fn) = (0, 0) corner, looking along the diagonal.
_ELEVATION_DEG, _AZIMUTH_DEG = 28.0, -135.0


def _success_grids(
    rows: Sequence[dict[str, object]],
    fusion: Sequence[str],
    pfp: Sequence[float],
    pfn: Sequence[float],
    views: Sequence[int],
) -> tuple[list[float], list[float], dict[tuple[str, int], np.ndarray]]:
    """Sorted P_fp and P_fn axes and, per (rule, view count), success (%) indexed [P_fn, P_fp]."""
    table = {(r["fusion"], r["pfp"], r["pfn"], r["views"]): r["success_rate"] for r in rows}
    xs, ys = sorted(set(pfp)), sorted(set(pfn))
    grids = {
        (rule, count): np.array([[100.0 * table[(rule, x, y, count)] for x in xs] for y in ys])
        for rule in fusion
        for count in views
    }
    return xs, ys, grids


def _trials_note(rows: Sequence[dict[str, object]]) -> str:
    trials = sorted({int(r["trials"]) for r in rows})
    return f"{trials[0]} trials per setting" if len(trials) == 1 else "trials vary by setting"


def _panel_grid(fig, n_rows: int, n_cols: int, panel: tuple[float, float], margins, gaps):
    """Place an n_rows x n_cols grid of panels (width, height in inches) with fixed margins
    (left, right, bottom, top) and gaps (across, down) in inches; returns the figure fractions
    (left, right, bottom, top). Fixed inches instead of a layout engine: constrained layout
    measures every artist, which costs seconds on these figures."""
    (w, h), (left, right, bottom, top), (gap_x, gap_y) = panel, margins, gaps
    width = left + n_cols * w + (n_cols - 1) * gap_x + right
    height = bottom + n_rows * h + (n_rows - 1) * gap_y + top
    fig.set_size_inches(width, height)
    box = (left / width, 1.0 - right / width, bottom / height, 1.0 - top / height)
    fig.subplots_adjust(left=box[0], right=box[1], bottom=box[2], top=box[3],
                        wspace=gap_x / w, hspace=gap_y / h)  # fmt: skip
    return box


@lru_cache(maxsize=512)
def _number_glyphs(text: str, size: float):
    """The outline of ``text`` at ``size`` points, centred on (0, 0), in points."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath
    from matplotlib.transforms import Affine2D

    path = TextPath((0, 0), text, prop=FontProperties(size=size))
    box = path.get_extents()
    return path.transformed(Affine2D().translate(-box.x0 - box.width / 2, -box.y0 - box.height / 2))


def _print_numbers(ax, values: np.ndarray, cmap, size: float):
    """Print every cell's value (rounded %) on an image of ``values`` in ``ax``, white on dark
    cells and black on light ones, as one collection of glyph outlines: a Text artist per cell
    (1452 of them in the default figure) costs seconds to draw, the collection milliseconds."""
    from matplotlib.collections import PathCollection
    from matplotlib.transforms import IdentityTransform

    rows, cols = np.indices(values.shape)
    rgb = cmap(values.ravel() / 100.0)[:, :3]
    dark = rgb @ np.array([0.299, 0.587, 0.114]) < 0.5
    numbers = PathCollection(
        [_number_glyphs(f"{v:.0f}", size) for v in values.ravel()], sizes=[1.0],
        offsets=np.column_stack([cols.ravel(), rows.ravel()]), offset_transform=ax.transData,
        transform=IdentityTransform(), facecolors=np.where(dark[:, None], 1.0, 0.0).repeat(3, 1),
        edgecolors="none", zorder=3,
    )  # fmt: skip
    ax.add_collection(numbers, autolim=False)
    return numbers


def draw_figure3(
    rows: Sequence[dict[str, object]],
    fusion: Sequence[str],
    pfp: Sequence[float],
    pfn: Sequence[float],
    views: Sequence[int],
) -> Figure:
    """The paper's Figure 3 as a figure to read numbers off: one heat map per rule (row) and
    view count (column), P_fp across, P_fn up, one fixed 0-100 % colour scale, and the success
    (%) printed in every cell. When one rate axis holds a single rate the panels are curves."""
    plt = _pyplot()
    xs, ys, grids = _success_grids(rows, fusion, pfp, pfn, views)
    n_rows, n_cols = len(fusion), len(views)
    if len(xs) == 1 or len(ys) == 1:
        return _figure3_curves(plt, xs, ys, grids, fusion, views, _trials_note(rows))
    cell = max(_CELL_INCHES, 3.0 / max(len(xs), len(ys)))
    panel = (cell * len(xs), cell * len(ys))
    fig, axes = plt.subplots(n_rows, n_cols, squeeze=False)
    _, right, bottom, top = _panel_grid(fig, n_rows, n_cols, panel, (0.8, 1.2, 0.75, 0.8),
                                        (0.25, 0.5))  # fmt: skip
    cmap = plt.get_cmap(SUCCESS_CMAP)
    size = min(10.0, 0.36 * 72.0 * cell)
    image = None
    for i, rule in enumerate(fusion):
        for j, count in enumerate(views):
            ax, z = axes[i, j], grids[(rule, count)]
            image = ax.imshow(z, origin="lower", cmap=cmap, vmin=0.0, vmax=100.0,
                              interpolation="nearest", aspect="equal")  # fmt: skip
            _print_numbers(ax, z, cmap, size)
            ax.set_title(f"{rule}, {count} views", fontsize=10)
            # Rates label the outer panels only: inner ticks would cost more than they say.
            ax.set_xticks([])
            ax.set_yticks([])
            if i == n_rows - 1:
                ax.set_xticks(range(len(xs)), [f"{x:g}" for x in xs], fontsize=8)
                ax.set_xlabel("P_fp (false-positive rate)", fontsize=9)
            if j == 0:
                ax.set_yticks(range(len(ys)), [f"{y:g}" for y in ys], fontsize=8)
                ax.set_ylabel("P_fn (false-negative rate)", fontsize=9)
    _bar_and_title(
        fig, image, (right, bottom, top), 0.6, 0.25,
        "Localization success (%): the grid's maximum is the object's cell or a neighbour "
        f"({_trials_note(rows)})",
    )  # fmt: skip
    return fig


def _figure3_curves(plt, xs, ys, grids, fusion, views, note):
    """Figure 3 when one rate axis holds a single rate: success (%) over the other."""
    n_rows, n_cols = len(fusion), len(views)
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(3.3 * n_cols, 3.0 * n_rows),
                             squeeze=False, layout="constrained")  # fmt: skip
    for i, rule in enumerate(fusion):
        for j, count in enumerate(views):
            ax, z = axes[i, j], grids[(rule, count)]
            if len(xs) > 1:
                axis, label, curve = xs, f"P_fp (P_fn = {ys[0]:g})", z[0]
            else:
                axis, label, curve = ys, f"P_fn (P_fp = {xs[0]:g})", z[:, 0]
            ax.plot(axis, curve, marker="o")
            ax.set_ylim(0, 100)
            ax.set_xlabel(label, fontsize=8)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=6, pad=0)
            ax.set_title(f"{rule}, {count} views", fontsize=9)
    fig.suptitle(f"Localization success (%), {note}")
    return fig


def figure3(
    path: Path,
    rows: Sequence[dict[str, object]],
    fusion: Sequence[str],
    pfp: Sequence[float],
    pfn: Sequence[float],
    views: Sequence[int],
) -> Path:
    """Write ``draw_figure3`` (heat maps, or curves over a single varied rate) as PNG."""
    return save_figure(draw_figure3(rows, fusion, pfp, pfn, views), path, tight=False)


def _diagonal_triangles(nx: int, ny: int) -> np.ndarray:
    """Two triangles per cell of an nx x ny vertex grid (vertex index j nx + i), each cell cut
    along its diagonal from (i + 1, j) to (i, j + 1).

    A grid quad whose corners do not lie in one plane (a success surface bends across most
    cells) has no flat face: mplot3d fills the quad's 2-D projection, whose edges cross at this
    view (saw teeth), and orders polygons by their mean depth alone, which puts a large bent
    quad in front of faces nearer the eye. Triangles are flat. This diagonal runs across the
    line of sight of the (0, 0)-corner view, so each cell's far triangle lies wholly behind its
    near one, and it follows the P_fp + P_fn = const ridges and valleys of the data rather than
    cutting through them.
    """
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    b, c, d = a + 1, a + nx + 1, a + nx
    return np.concatenate([np.stack([a, b, d], axis=1), np.stack([b, c, d], axis=1)])


def draw_figure3_3d(
    rows: Sequence[dict[str, object]],
    fusion: Sequence[str],
    pfp: Sequence[float],
    pfn: Sequence[float],
    views: Sequence[int],
) -> Figure | None:
    """The paper's look: success (%) as a surface over P_fp x P_fn, a panel per rule and view
    count, drawn as flat triangles (see ``_diagonal_triangles``). None when one rate axis holds
    a single rate: there is no surface, and ``draw_figure3`` draws the curves."""
    from matplotlib.colors import Normalize
    from matplotlib.tri import Triangulation

    plt = _pyplot()
    xs, ys, grids = _success_grids(rows, fusion, pfp, pfn, views)
    if len(xs) == 1 or len(ys) == 1:
        return None
    gx, gy = np.meshgrid(xs, ys)
    mesh = Triangulation(gx.ravel(), gy.ravel(), _diagonal_triangles(len(xs), len(ys)))
    n_rows, n_cols = len(fusion), len(views)
    fig = plt.figure()
    norm = Normalize(0.0, 100.0)
    surface = None
    for i, rule in enumerate(fusion):
        for j, count in enumerate(views):
            ax = fig.add_subplot(n_rows, n_cols, i * n_cols + j + 1, projection="3d")
            surface = ax.plot_trisurf(mesh, grids[(rule, count)].ravel(), cmap=SUCCESS_CMAP,
                                      norm=norm, edgecolor="k", linewidth=0.15)  # fmt: skip
            ax.set_zlim(0, 100)
            # Few ticks: each costs milliseconds in mplot3d, and figure3.png has the numbers.
            ax.set_xticks([xs[0], (xs[0] + xs[-1]) / 2, xs[-1]])
            ax.set_yticks([ys[0], (ys[0] + ys[-1]) / 2, ys[-1]])
            ax.set_zticks([0, 50, 100])
            ax.set_xlabel("P_fp", fontsize=7, labelpad=-4)
            ax.set_ylabel("P_fn", fontsize=7, labelpad=-4)
            ax.view_init(elev=_ELEVATION_DEG, azim=_AZIMUTH_DEG)
            ax.tick_params(labelsize=6, pad=0)
            ax.set_title(f"{rule}, {count} views", fontsize=9)
    _, right, bottom, top = _panel_grid(fig, n_rows, n_cols, (3.4, 3.0), (0.1, 1.1, 0.1, 0.6),
                                        (0.1, 0.4))  # fmt: skip
    _bar_and_title(
        fig, surface, (right, bottom, top), 0.5, 0.2,
        "Localization success (%) over false-positive and false-negative rates "
        f"({_trials_note(rows)}); figure3.png gives the numbers",
    )  # fmt: skip
    return fig


def _bar_and_title(fig, mappable, panels, share: float, title_gap: float, title: str) -> None:
    """A success colour bar right of the panels (``share`` of their height, centred) and the
    title ``title_gap`` inches below the top edge; ``panels`` is (right, bottom, top) in figure
    fractions."""
    right, bottom, top = panels
    width, height = fig.get_size_inches()
    span = top - bottom
    bar = fig.add_axes(
        (right + 0.3 / width, bottom + 0.5 * (1 - share) * span, 0.18 / width, share * span)
    )
    fig.colorbar(mappable, cax=bar, label="localization success (%)")
    fig.suptitle(title, y=1.0 - title_gap / height)


def figure3_3d(
    path: Path,
    rows: Sequence[dict[str, object]],
    fusion: Sequence[str],
    pfp: Sequence[float],
    pfn: Sequence[float],
    views: Sequence[int],
) -> Path | None:
    """Write ``draw_figure3_3d`` as PNG; None (nothing written) without a surface to draw."""
    fig = draw_figure3_3d(rows, fusion, pfp, pfn, views)
    return None if fig is None else save_figure(fig, path, tight=False)


def draw_threshold_figure(
    rows: Sequence[dict[str, object]], fusion: Sequence[str], views: Sequence[int]
) -> Figure:
    """Monte Carlo with continuous scores: success (%) over the detector threshold, a panel per
    view count and a line per rule (``fusion`` names the rows' ``fusion`` values). Only
    ``logodds`` uses the threshold; the other rules' lines are flat, the same worlds scored
    again, so they are the reference it is read against."""
    plt = _pyplot()
    table = {(r["fusion"], r["threshold"], r["views"]): r["success_rate"] for r in rows}
    thresholds = sorted({float(r["threshold"]) for r in rows})
    # A rule keeps its colour with and without visibility ("RULE+visibility": solid; blind:
    # dashed when the other is drawn too), so the pair reads as one rule.
    bases = list(dict.fromkeys(rule.split("+")[0] for rule in fusion))
    cycle = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    paired = any("+" in rule for rule in fusion)
    fig, axes = plt.subplots(1, len(views), figsize=(3.4 * len(views) + 1.6, 3.2),
                             squeeze=False, layout="constrained")  # fmt: skip
    for ax, count in zip(axes[0], views, strict=True):
        for rule in fusion:
            curve = [100.0 * table[(rule, t, count)] for t in thresholds]
            colour = cycle[bases.index(rule.split("+")[0]) % len(cycle)]
            style = "--" if paired and "+" not in rule else "-"
            ax.plot(thresholds, curve, style, color=colour, marker="o", ms=3, label=rule)
        ax.set_ylim(0, 100)
        ax.set_xlabel("threshold (logodds fires at score >= it)", fontsize=8)
        ax.set_title(f"{count} views", fontsize=9)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    axes[0, 0].set_ylabel("localization success (%)", fontsize=8)
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside right center", fontsize=7)
    fig.suptitle(f"Localization success with continuous scores ({_trials_note(rows)})")
    return fig


def threshold_figure(
    path: Path, rows: Sequence[dict[str, object]], fusion: Sequence[str], views: Sequence[int]
) -> Path:
    """Write ``draw_threshold_figure`` as PNG."""
    return save_figure(draw_threshold_figure(rows, fusion, views), path, tight=False)


def grid_figure(
    path: Path,
    layer: np.ndarray,
    extent: tuple[float, float, float, float],
    title: str,
    furniture: Sequence[tuple[str, np.ndarray]] = (),
    estimate: tuple[float, float] | None = None,
    truth: tuple[float, float] | None = None,
) -> Path:
    """One accumulator layer drawn like the paper's Figure 2(b): brighter is more confident.

    ``layer`` is indexed [row, col] with row 0 at the bottom (map y up); ``furniture`` holds
    (name, k x 2 outline in metres) pairs drawn as outlines over the grid, with the room's edge,
    the estimate (a cross) and, in the simulation, the truth (a circle).
    """
    plt = _pyplot()
    x0, y0, x1, y1 = extent
    fig, ax = plt.subplots(figsize=(4.2, 4.2 * (y1 - y0) / (x1 - x0) + 0.9))
    image = ax.imshow(layer, origin="lower", extent=(x0, x1, y0, y1), cmap="gray",
                      interpolation="nearest")  # fmt: skip
    fig.colorbar(image, ax=ax, fraction=0.046, pad=0.04, label="accumulated match")
    ax.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], color="tab:blue", lw=1.5)
    for name, outline in furniture:
        closed = np.vstack([outline, outline[:1]])
        ax.plot(closed[:, 0], closed[:, 1], color="tab:orange", lw=0.9)
        if is_wall(name):
            continue
        centre = outline.mean(axis=0)
        ax.text(centre[0], centre[1], name.replace("_", " "), color="tab:orange", fontsize=6,
                ha="center", va="center")  # fmt: skip
    if truth is not None:
        ax.plot(*truth, marker="o", ms=11, mfc="none", mec="tab:green", mew=1.8, label="truth")
    if estimate is not None:
        ax.plot(*estimate, marker="x", ms=9, color="tab:red", mew=2.0, label="estimate")
    if truth is not None or estimate is not None:
        # below the map: inside, it covered whatever stood in its corner (a counter's tin)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, fontsize=7)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=9)
    return save_figure(fig, path)
