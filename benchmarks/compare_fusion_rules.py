"""Where the normalized and log-odds rules beat or lose to the paper's accumulate rule.

    twin montecarlo --out runs/montecarlo
    python benchmarks/compare_fusion_rules.py runs/montecarlo/results.csv

Splits the settings into the informative region (P_fp + P_fn < 1: a firing is more likely at the
object than elsewhere) and the rest, where only a rule told the rates (log-odds) can use the
detector by inverting it. Prints, per view count, the mean success of each rule and how many
settings each alternative wins or loses by more than 10 points. A sweep with occluders scores
each rule blind and knowing what was in view: the latter appear as RULE+visibility, compared
with the blind accumulate rule.
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict


def main(path: str) -> None:
    rate: dict[tuple[str, float, float, int], float] = {}
    with open(path, encoding="utf-8") as handle:
        for row in csv.DictReader(handle):
            rule = row["fusion"]
            if row.get("visibility", "none") != "none":
                rule = f"{rule}+visibility"
            key = (rule, float(row["pfp"]), float(row["pfn"]), int(row["views"]))
            rate[key] = float(row["success_rate"])
    rules = sorted({k[0] for k in rate})
    views = sorted({k[3] for k in rate})
    settings = sorted({(k[1], k[2]) for k in rate})
    if "accumulate" not in rules:
        sys.exit("results.csv has no (blind) accumulate rows to compare against")
    regions = {
        "informative (P_fp + P_fn < 1)": [s for s in settings if s[0] + s[1] < 1 - 1e-9],
        "uninformative or inverted (P_fp + P_fn >= 1)": [
            s for s in settings if s[0] + s[1] >= 1 - 1e-9
        ],
    }
    for region, members in regions.items():
        if not members:
            continue
        print(f"{region}: {len(members)} settings")
        for v in views:
            means = defaultdict(float)
            for rule in rules:
                means[rule] = 100 * sum(rate[(rule, *s, v)] for s in members) / len(members)
            line = "  ".join(f"{rule} {means[rule]:5.1f}%" for rule in rules)
            print(f"  {v:4d} views  mean success: {line}")
            for rule in rules:
                if rule == "accumulate":
                    continue
                diffs = [rate[(rule, *s, v)] - rate[("accumulate", *s, v)] for s in members]
                wins = sum(d > 0.10 for d in diffs)
                losses = sum(d < -0.10 for d in diffs)
                worst = min(diffs)
                best = max(diffs)
                print(
                    f"             {rule} vs accumulate: wins {wins}, loses {losses} "
                    f"(by > 10 points); range {100 * worst:+.0f} .. {100 * best:+.0f} points"
                )


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python benchmarks/compare_fusion_rules.py RESULTS_CSV")
    main(sys.argv[1])
