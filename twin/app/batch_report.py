"""A batch's report: one row per run (``summary.csv``), the summary (``summary.json``), plots.

Success is an estimate within the batch's tolerance of the truth; the plots show the error
distribution and the success rate against every varied factor.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from twin.app.batch import BatchSpec
from twin.core.errors import TwinError
from twin.core.store import write_text_atomic

SUMMARY_COLUMNS = (
    "run", "success", "error_m", "truth_x", "truth_y", "estimate_x", "estimate_y", "surface",
    "lighting", "threshold", "peak", "peak_ratio", "views", "setup_s", "move_s", "capture_s",
    "detect_s", "fuse_s", "mission_s", "reused_world", "time_s", "path_length_m", "stopped",
)  # fmt: skip


def target_name(results: Sequence[dict[str, Any]]) -> str:
    """The object scored in the summary: the first with ground truth."""
    for name, entry in results[0]["objects"].items():
        if "error_m" in entry:
            return name
    raise TwinError("no object of the batch has ground truth; give each object a scene body")


def summary_rows(results: Sequence[dict[str, Any]], tolerance: float) -> list[dict[str, Any]]:
    name = target_name(results)
    rows = []
    for r in results:
        entry, t = r["objects"][name], r["timings_s"]
        rows.append({
            "run": r["run"],
            # a mission the robot could not finish failed, wherever its estimate was
            "success": int(entry["error_m"] <= tolerance and "failed" not in r),
            "error_m": entry["error_m"],
            "truth_x": entry["truth_m"][0], "truth_y": entry["truth_m"][1],
            "estimate_x": entry["estimate_m"][0], "estimate_y": entry["estimate_m"][1],
            "surface": entry.get("surface", ""),
            "lighting": round(r["lighting"], 4), "threshold": round(r["threshold"], 4),
            "peak": entry["peak"], "peak_ratio": entry["peak_ratio"], "views": r["views"],
            "setup_s": t["setup"], "move_s": t["move"], "capture_s": t["capture"],
            "detect_s": t["detect"], "fuse_s": t["fuse"], "mission_s": t["mission"],
            "reused_world": int(r["reused_world"]),
            # robot time and metres driven (older journals have neither), why a search stopped
            "time_s": r.get("time_s", ""), "path_length_m": r.get("path_length_m", ""),
            "stopped": r.get("search", {}).get("stopped", ""),
        })  # fmt: skip
    return rows


def summarize(
    spec: BatchSpec, results: Sequence[dict[str, Any]], wall_s: float | None = None
) -> dict[str, Any]:
    """Success rate within the tolerance, the error distribution and the timings."""
    rows = summary_rows(results, spec.tolerance)
    errors = np.array([r["error_m"] for r in rows])
    hits = int(sum(r["success"] for r in rows))
    timing_keys = ("setup_s", "move_s", "capture_s", "detect_s", "fuse_s", "mission_s")
    summary: dict[str, Any] = {
        "target": target_name(results),
        "runs": len(rows),
        "seed": spec.seed,
        "vary": list(spec.vary),
        "lighting_range": list(spec.lighting),
        "threshold_range": list(spec.threshold),
        "tolerance_m": spec.tolerance,
        "successes": hits,
        "success_rate": hits / len(rows),
        "error_m": {
            "mean": float(errors.mean()),
            "median": float(np.median(errors)),
            "p90": float(np.percentile(errors, 90)),
            "min": float(errors.min()),
            "max": float(errors.max()),
        },
        "timings_s": {
            k[:-2]: {
                "mean": float(np.mean([r[k] for r in rows])),
                "total": float(np.sum([r[k] for r in rows])),
            }
            for k in timing_keys
        },
        "worlds_reused": int(sum(r["reused_world"] for r in rows)),
        "mission": spec.mission,
        "views": _spread([r["views"] for r in rows]),
    }
    for key in ("time_s", "path_length_m"):
        if all(r[key] != "" for r in rows):
            summary[key] = _spread([r[key] for r in rows])
    if wall_s is not None:
        summary["wall_s"] = round(wall_s, 3)
    return summary


def _spread(values: Sequence[float]) -> dict[str, float]:
    """Median, 90th percentile and mean: what a search's views, time and path are read by."""
    a = np.asarray(values, dtype=float)
    return {
        "median": float(np.median(a)),
        "p90": float(np.percentile(a, 90)),
        "mean": float(a.mean()),
    }


def write_summary(
    out: Path, spec: BatchSpec, results: Sequence[dict[str, Any]], wall_s: float | None = None
) -> tuple[dict[str, Any], list[Path]]:
    """``summary.csv`` (one row per run), ``summary.json`` and the plots; returns the summary."""
    rows = summary_rows(results, spec.tolerance)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    paths = [write_text_atomic(out / "summary.csv", buffer.getvalue())]
    summary = summarize(spec, results, wall_s)
    paths.append(write_text_atomic(out / "summary.json", json.dumps(summary, indent=1)))
    paths.append(_error_histogram(out / "errors.png", rows, spec.tolerance))
    factors = {"target": "surface", "lighting": "lighting", "threshold": "threshold"}
    for factor in spec.vary:
        paths.append(_success_vs(out / f"success_vs_{factor}.png", rows, factors[factor]))
    return summary, paths


def _error_histogram(path: Path, rows: list[dict[str, Any]], tolerance: float) -> Path:
    from twin.app.plots import _pyplot, save_figure  # TODO(plots): one public pyplot()

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    errors = [r["error_m"] for r in rows]
    ax.hist(errors, bins=min(30, max(5, len(errors) // 3)), color="#4477aa")
    ax.axvline(tolerance, color="#cc3311", linestyle="--", label=f"success radius {tolerance} m")
    ax.set_xlabel("estimate error (m)")
    ax.set_ylabel("runs")
    ax.set_title(f"{len(rows)} runs: {100 * np.mean([r['success'] for r in rows]):.0f} % success")
    ax.legend()
    return save_figure(fig, path)


def _success_vs(path: Path, rows: list[dict[str, Any]], key: str) -> Path:
    """Success rate per furniture top, or per bin (about 5) of a numeric factor."""
    from twin.app.plots import _pyplot, save_figure  # TODO(plots): one public pyplot()

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    if key == "surface":
        labels = sorted({r[key] for r in rows})
        groups = [[r["success"] for r in rows if r[key] == label] for label in labels]
        ax.set_xlabel("furniture the target stands on")
    else:
        values = np.array([r[key] for r in rows])
        edges = np.linspace(values.min(), values.max() + 1e-9, min(5, len(rows)) + 1)
        which = np.clip(np.digitize(values, edges) - 1, 0, len(edges) - 2)
        labels = [f"{edges[i]:.2f}-{edges[i + 1]:.2f}" for i in range(len(edges) - 1)]
        groups = [[r["success"] for r, w in zip(rows, which, strict=True) if w == i]
                  for i in range(len(labels))]  # fmt: skip
        ax.set_xlabel("light scale" if key == "lighting" else "detector threshold")
    rates = [100 * np.mean(g) if g else 0.0 for g in groups]
    bars = ax.bar(range(len(labels)), rates, color="#228833")
    for bar, group in zip(bars, groups, strict=True):
        ax.annotate(f"n={len(group)}", (bar.get_x() + bar.get_width() / 2, bar.get_height()),
                    ha="center", va="bottom", fontsize=8)  # fmt: skip
    ax.set_xticks(range(len(labels)), labels, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("success (%)")
    ax.set_ylim(0, 110)
    return save_figure(fig, path)
