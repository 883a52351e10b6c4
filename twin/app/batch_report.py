"""A batch's report: one row per run (``summary.csv``), the summary (``summary.json``), plots.

Each object with ground truth is scored in each run: success is its estimate within the batch's
tolerance of the truth in the plan and, when a height tolerance is given, in height. The plots
show the plan error's distribution and the success rate against every varied factor.
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
    "run", "object", "success", "error_m", "height_error_m", "truth_x", "truth_y", "truth_z",
    "estimate_x", "estimate_y", "estimate_z", "surface", "lighting", "threshold", "peak",
    "peak_ratio", "views", "setup_s", "move_s", "capture_s", "detect_s", "fuse_s", "mission_s",
    "reused_world", "time_s", "path_length_m", "stopped",
)  # fmt: skip


def scored_objects(results: Sequence[dict[str, Any]]) -> list[str]:
    """The objects the summary scores: every one with ground truth (a scene body)."""
    names = [name for name, entry in results[0]["objects"].items() if "error_m" in entry]
    if not names:
        raise TwinError("no object of the batch has ground truth; give each object a scene body")
    return names


def _succeeded(entry: dict[str, Any], tolerance: float, height_tolerance: float | None) -> bool:
    """Within the plan's tolerance, and (when one is asked) the height's: an object whose
    height is unknown misses a height tolerance."""
    if entry["error_m"] > tolerance:
        return False
    if height_tolerance is None:
        return True
    height_error = entry.get("height_error_m")
    return height_error is not None and height_error <= height_tolerance


def summary_rows(
    results: Sequence[dict[str, Any]], tolerance: float, height_tolerance: float | None = None
) -> list[dict[str, Any]]:
    """One row per run and scored object (the run's own columns repeated on each)."""
    rows = []
    for r in results:
        t = r["timings_s"]
        for name in scored_objects(results):
            entry = r["objects"][name]
            truth, estimate = list(entry["truth_m"]), list(entry["estimate_m"])
            truth += [None] * (3 - len(truth))
            estimate += [None] * (3 - len(estimate))
            rows.append({
                "run": r["run"], "object": name,
                # a mission the robot could not finish failed, wherever its estimate was
                "success": int(_succeeded(entry, tolerance, height_tolerance)
                               and "failed" not in r),
                "error_m": entry["error_m"], "height_error_m": entry.get("height_error_m"),
                "truth_x": truth[0], "truth_y": truth[1], "truth_z": truth[2],
                "estimate_x": estimate[0], "estimate_y": estimate[1], "estimate_z": estimate[2],
                "surface": entry.get("surface", ""),
                "lighting": round(r["lighting"], 4), "threshold": round(r["threshold"], 4),
                "peak": entry["peak"], "peak_ratio": entry["peak_ratio"], "views": r["views"],
                "setup_s": t["setup"], "move_s": t["move"], "capture_s": t["capture"],
                "detect_s": t["detect"], "fuse_s": t["fuse"], "mission_s": t["mission"],
                "reused_world": int(r["reused_world"]),
                # robot time and metres driven (older journals have neither), why a search
                # stopped
                "time_s": r.get("time_s", ""), "path_length_m": r.get("path_length_m", ""),
                "stopped": r.get("search", {}).get("stopped", ""),
            })  # fmt: skip
    return rows


def _errors(values: Sequence[float | None]) -> dict[str, float | int] | None:
    known = np.array([v for v in values if v is not None], dtype=float)
    if known.size == 0:
        return None
    return {
        "mean": float(known.mean()),
        "median": float(np.median(known)),
        "p90": float(np.percentile(known, 90)),
        "min": float(known.min()),
        "max": float(known.max()),
        "unknown": len(values) - int(known.size),
    }


def summarize(
    spec: BatchSpec, results: Sequence[dict[str, Any]], wall_s: float | None = None
) -> dict[str, Any]:
    """Success rate within the tolerances, per object and over all, the error distributions
    (in the plan, and in height where known) and the timings."""
    rows = summary_rows(results, spec.tolerance, spec.height_tolerance)
    names = scored_objects(results)
    runs = [r for r in rows if r["object"] == names[0]]  # one row per run, for its own columns
    hits = int(sum(r["success"] for r in rows))
    timing_keys = ("setup_s", "move_s", "capture_s", "detect_s", "fuse_s", "mission_s")
    per_object = {}
    for name in names:
        mine = [r for r in rows if r["object"] == name]
        done = int(sum(r["success"] for r in mine))
        per_object[name] = {
            "successes": done,
            "success_rate": done / len(mine),
            "error_m": _errors([r["error_m"] for r in mine]),
            "height_error_m": _errors([r["height_error_m"] for r in mine]),
        }
    summary: dict[str, Any] = {
        "target": names[0] if len(names) == 1 else names,
        "objects": per_object,
        "runs": len(runs),
        "seed": spec.seed,
        "vary": list(spec.vary),
        "lighting_range": list(spec.lighting),
        "threshold_range": list(spec.threshold),
        "tolerance_m": spec.tolerance,
        "height_tolerance_m": spec.height_tolerance,
        "successes": hits,
        "success_rate": hits / len(rows),
        "error_m": _errors([r["error_m"] for r in rows]),
        "height_error_m": _errors([r["height_error_m"] for r in rows]),
        "timings_s": {
            k[:-2]: {
                "mean": float(np.mean([r[k] for r in runs])),
                "total": float(np.sum([r[k] for r in runs])),
            }
            for k in timing_keys
        },
        "worlds_reused": int(sum(r["reused_world"] for r in runs)),
        "mission": spec.mission,
        "views": _spread([r["views"] for r in runs]),
    }
    for key in ("time_s", "path_length_m"):
        if all(r[key] != "" for r in runs):
            summary[key] = _spread([r[key] for r in runs])
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
    rows = summary_rows(results, spec.tolerance, spec.height_tolerance)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    paths = [write_text_atomic(out / "summary.csv", buffer.getvalue())]
    summary = summarize(spec, results, wall_s)
    paths.append(write_text_atomic(out / "summary.json", json.dumps(summary, indent=1)))
    paths.append(_error_histogram(out / "errors.png", rows, spec.tolerance))
    # (the camera's noise seed has no order to plot success against)
    factors = {"target": "surface", "lighting": "lighting", "threshold": "threshold"}
    for factor in (f for f in spec.vary if f in factors):
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
    what = "runs" if len({r["object"] for r in rows}) == 1 else "objects found in runs"
    ax.set_title(f"{len(rows)} {what}: {100 * np.mean([r['success'] for r in rows]):.0f} % success")
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
