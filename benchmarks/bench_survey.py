"""Wall time and peak memory of the default survey mission, from command start to result.

    python benchmarks/bench_survey.py

Runs ``twin survey`` (the shipped config: 5 stops x 8 views in the simulated living room) in a
fresh process twice: once with an empty model cache (so training the rice box's RFCH model from
the training stage is included) and once with the cache warm, the way a user re-runs it. Prints
the wall time measured outside the process, the split the run reports in result.json, and the
process's peak resident memory.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def run_once(folder: Path, label: str) -> None:
    out = folder / f"run-{label}"
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "twin.cli", "survey", "--out", str(out), "--quiet"],
        cwd=folder,
        check=True,
    )
    wall = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    result = json.loads((out / "result.json").read_text())
    box = result["objects"]["rice_box"]
    split = ", ".join(f"{k} {v:.2f}" for k, v in result["timings_s"].items())
    print(f"{label}: {wall:.1f} s wall from command start to result ({result['views']} views)")
    print(f"  timings_s: {split}")
    print(f"  peak memory (max RSS of the run's process): {max(peak, before) / 1024:.0f} MiB")
    print(
        f"  estimate {box['estimate_m']} m, error {box['error_m']:.2f} m, "
        f"first/second peak {box['peak_ratio']:.2f}"
    )


def main() -> None:
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        run_once(folder, "cold cache (trains the model)")
        run_once(folder, "warm cache")


if __name__ == "__main__":
    main()
