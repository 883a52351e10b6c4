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


def figure3(
    path: Path,
    rows: Sequence[dict[str, object]],
    fusion: Sequence[str],
    pfp: Sequence[float],
    pfn: Sequence[float],
    views: Sequence[int],
) -> Path:
    """The paper's Figure 3: success (%) over P_fp x P_fn, a panel per view count, a row per rule.

    With both rate axes varied the panels are 3-D surfaces as in the paper; when one axis holds
    a single rate they become curves over the other.
    """
    plt = _pyplot()
    table = {(r["fusion"], r["pfp"], r["pfn"], r["views"]): r["success_rate"] for r in rows}
    xs, ys = sorted(set(pfp)), sorted(set(pfn))
    surface = len(xs) > 1 and len(ys) > 1
    n_rows, n_cols = len(fusion), len(views)
    fig = plt.figure(figsize=(3.3 * n_cols, 3.0 * n_rows))
    for i, rule in enumerate(fusion):
        for j, count in enumerate(views):
            z = np.array([[100.0 * table[(rule, x, y, count)] for x in xs] for y in ys])
            index = i * n_cols + j + 1
            if surface:
                ax = fig.add_subplot(n_rows, n_cols, index, projection="3d")
                gx, gy = np.meshgrid(xs, ys)
                ax.plot_surface(gx, gy, z, cmap="viridis", vmin=0, vmax=100, edgecolor="k",
                                linewidth=0.2)  # fmt: skip
                ax.set_zlim(0, 100)
                ax.set_xlabel("P_fp", fontsize=7, labelpad=-4)
                ax.set_ylabel("P_fn", fontsize=7, labelpad=-4)
                ax.view_init(elev=28, azim=-135)
            else:
                ax = fig.add_subplot(n_rows, n_cols, index)
                axis, label, curve = (xs, "P_fp", z[0]) if len(xs) > 1 else (ys, "P_fn", z[:, 0])
                ax.plot(axis, curve, marker="o")
                ax.set_ylim(0, 100)
                ax.set_xlabel(label, fontsize=8)
                ax.grid(alpha=0.3)
            ax.tick_params(labelsize=6, pad=0)
            ax.set_title(f"{rule}: {count} views", fontsize=9)
    fig.suptitle("Localization success (%) over false-positive and false-negative rates")
    fig.tight_layout()
    return save_figure(fig, path)


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
