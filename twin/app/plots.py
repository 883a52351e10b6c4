"""Figures, drawn headless with matplotlib's Agg backend and written atomically as PNG."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from twin.core.store import write_atomic


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: Path, dpi: int = 110) -> Path:
    """Render ``fig`` to PNG bytes, then write them atomically; the figure is closed."""
    plt = _pyplot()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
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


def draw_figure3(
    rows: Sequence[dict[str, object]],
    fusion: Sequence[str],
    pfp: Sequence[float],
    pfn: Sequence[float],
    views: Sequence[int],
):
    """The paper's Figure 3 as a figure to read numbers off: one heat map per rule (row) and
    view count (column), P_fp across, P_fn up, one fixed 0-100 % colour scale, and the success
    (%) printed in every cell. When one rate axis holds a single rate the panels are curves."""
    plt = _pyplot()
    xs, ys, grids = _success_grids(rows, fusion, pfp, pfn, views)
    n_rows, n_cols = len(fusion), len(views)
    if len(xs) == 1 or len(ys) == 1:
        return _figure3_curves(plt, xs, ys, grids, fusion, views, _trials_note(rows))
    side = max(3.2, _CELL_INCHES * max(len(xs), len(ys)))
    fig, axes = plt.subplots(
        n_rows, n_cols, figsize=(side * n_cols + 1.2, side * n_rows + 0.8), squeeze=False,
        sharex=True, sharey=True, layout="constrained",
    )  # fmt: skip
    cmap = plt.get_cmap(SUCCESS_CMAP)
    cell_points = 72.0 * side / max(len(xs), len(ys))
    fontsize = min(10.0, 0.36 * cell_points)
    image = None
    for i, rule in enumerate(fusion):
        for j, count in enumerate(views):
            ax, z = axes[i, j], grids[(rule, count)]
            image = ax.imshow(z, origin="lower", cmap=cmap, vmin=0.0, vmax=100.0,
                              interpolation="nearest", aspect="equal")  # fmt: skip
            for (row, col), value in np.ndenumerate(z):
                r, g, b, _ = cmap(value / 100.0)
                dark = 0.299 * r + 0.587 * g + 0.114 * b < 0.5
                ax.text(col, row, f"{value:.0f}", ha="center", va="center", fontsize=fontsize,
                        color="white" if dark else "black")  # fmt: skip
            ax.set_xticks(range(len(xs)), [f"{x:g}" for x in xs], fontsize=8)
            ax.set_yticks(range(len(ys)), [f"{y:g}" for y in ys], fontsize=8)
            ax.set_title(f"{rule}, {count} views", fontsize=10)
            if i == n_rows - 1:
                ax.set_xlabel("P_fp (false-positive rate)", fontsize=8)
            if j == 0:
                ax.set_ylabel("P_fn (false-negative rate)", fontsize=8)
    fig.colorbar(image, ax=axes, shrink=0.6, aspect=30, label="localization success (%)")
    fig.suptitle(
        "Localization success (%): the grid's maximum is the object's cell or a neighbour "
        f"({_trials_note(rows)})"
    )
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
    fig.suptitle(f"Localization success (%) ({note})")
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
    return save_figure(draw_figure3(rows, fusion, pfp, pfn, views), path)


def _diagonal_triangles(nx: int, ny: int) -> np.ndarray:
    """Two triangles per cell of an nx x ny vertex grid (vertex index j nx + i), each cell cut
    along its diagonal from (i + 1, j) to (i, j + 1).

    A grid quad whose corners do not lie in one plane (a success surface bends across most
    cells) has no flat face: mplot3d fills the quad's 2-D projection, whose edges cross at this
    view (saw teeth), and sorts it by one mean depth, so it is painted over nearer faces.
    Triangles are flat. This diagonal runs across the line of sight of the (0, 0)-corner view,
    so each cell's far triangle lies wholly behind its near one, and it follows the
    P_fp + P_fn = const ridges and valleys of the data rather than cutting through them.
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
):
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
    fig = plt.figure(figsize=(3.6 * n_cols + 1.0, 3.3 * n_rows), layout="constrained")
    norm = Normalize(0.0, 100.0)
    surface = None
    axes = []
    for i, rule in enumerate(fusion):
        for j, count in enumerate(views):
            ax = fig.add_subplot(n_rows, n_cols, i * n_cols + j + 1, projection="3d")
            surface = ax.plot_trisurf(mesh, grids[(rule, count)].ravel(), cmap=SUCCESS_CMAP,
                                      norm=norm, edgecolor="k", linewidth=0.15)  # fmt: skip
            ax.set_zlim(0, 100)
            ax.set_xlabel("P_fp", fontsize=7, labelpad=-4)
            ax.set_ylabel("P_fn", fontsize=7, labelpad=-4)
            ax.view_init(elev=_ELEVATION_DEG, azim=_AZIMUTH_DEG)
            ax.tick_params(labelsize=6, pad=0)
            ax.set_title(f"{rule}, {count} views", fontsize=9)
            axes.append(ax)
    fig.colorbar(surface, ax=axes, shrink=0.5, aspect=30, label="localization success (%)")
    fig.suptitle(
        "Localization success (%) over false-positive and false-negative rates "
        f"({_trials_note(rows)}); figure3.png gives the numbers"
    )
    return fig


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
    return None if fig is None else save_figure(fig, path)


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
    fig, ax = plt.subplots(figsize=(4.2, 4.2 * (y1 - y0) / (x1 - x0) + 0.6))
    image = ax.imshow(layer, origin="lower", extent=(x0, x1, y0, y1), cmap="gray",
                      interpolation="nearest")  # fmt: skip
    fig.colorbar(image, ax=ax, fraction=0.046, pad=0.04, label="accumulated match")
    ax.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], color="tab:blue", lw=1.5)
    for name, outline in furniture:
        closed = np.vstack([outline, outline[:1]])
        ax.plot(closed[:, 0], closed[:, 1], color="tab:orange", lw=0.9)
        centre = outline.mean(axis=0)
        ax.text(centre[0], centre[1], name.replace("_", " "), color="tab:orange", fontsize=6,
                ha="center", va="center")  # fmt: skip
    if truth is not None:
        ax.plot(*truth, marker="o", ms=11, mfc="none", mec="tab:green", mew=1.8, label="truth")
    if estimate is not None:
        ax.plot(*estimate, marker="x", ms=9, color="tab:red", mew=2.0, label="estimate")
    if truth is not None or estimate is not None:
        ax.legend(loc="upper right", fontsize=7, framealpha=0.7)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=9)
    return save_figure(fig, path)
