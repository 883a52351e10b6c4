"""Figures, drawn headless with matplotlib's Agg backend and written atomically as PNG."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from twin.store import write_atomic


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
