#!/usr/bin/env python3
"""How a fleet plan's cost grows with the number of robots (issue 33, docs/performance.md).

For each floor and each M, M robots between free cells drawn with a fixed seed, every robot
asking for its ends' weaker value minus a margin (so routes lean on the IRS and the robots
contend for it), planned by `irs-planner fleet`; the plan's own time (`took_ms`, the map's
build excluded) is the median of `--repeat` runs. Prints one row per (floor, access, M).

    scripts/fleet-scaling.py [--binary target/release/irs-planner] [--repeat 3]
"""

import argparse
import json
import math
import os
import random
import statistics
import subprocess
import tempfile

FLOORS = [
    # (label, scenario, unit, margin below the weaker end's value, access, robot counts)
    ("paper", "scenarios/paper-single-user.json", "gain_db", 3.0, None, [1, 2, 4, 8, 16, 32]),
    ("paper", "scenarios/paper-single-user.json", "bps_hz", None, "noma", [1, 2, 4, 8, 16]),
    ("paper", "scenarios/paper-single-user.json", "bps_hz", None, "oma", [4, 8]),
    ("warehouse", "scenarios/warehouse/warehouse.json", "gain_db", 3.0, None, [1, 2, 4, 8, 16]),
]


def run(binary, args):
    out = subprocess.run([binary, *args], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def free_cells(binary, scenario):
    body = run(binary, ["map", "--scenario", scenario, "--kind", "gain", "--quiet"])
    grid, values = body["grid"], body["values"]
    cells = []
    for i, column in enumerate(values):
        for j, v in enumerate(column):
            if v is not None:
                x = grid["x_min"] + i * grid["resolution_m"]
                y = grid["y_min"] + j * grid["resolution_m"]
                cells.append((x, y, v))
    return cells


def robots_for(cells, m, unit, margin, seed):
    rng = random.Random(seed)
    robots = []
    used = set()
    while len(robots) < m:
        a, b = rng.sample(cells, 2)
        if (a[0], a[1]) in used or (b[0], b[1]) in used:
            continue
        used.update({(a[0], a[1]), (b[0], b[1])})
        weaker = min(a[2], b[2])
        if unit == "gain_db":
            threshold = weaker - margin
        else:
            # A quarter of the rate its weaker end gives alone with all the power (paper
            # floor: 20 dBm transmitted, -90 dBm of noise): the robots of one AP must share it.
            snr = 10 ** ((weaker + 20 + 90) / 10)
            threshold = round(math.log2(1 + snr) / 4, 2)
        robots.append({"start": [a[0], a[1]], "goal": [b[0], b[1]], "threshold": threshold})
    return robots


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--binary", default="target/release/irs-planner")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print("| floor | access | M | served | space-time | steps | took_ms (median) |")
    print("|---|---|---|---|---|---|---|")
    cache = {}
    for label, scenario, unit, margin, access, counts in FLOORS:
        cells = cache.setdefault(scenario, free_cells(args.binary, scenario))
        for m in counts:
            query = {"unit": unit, "robots": robots_for(cells, m, unit, margin, seed=m)}
            if access:
                query["access"] = access
            with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
                json.dump(query, f)
            times = []
            try:
                for _ in range(args.repeat):
                    plan = run(args.binary, ["fleet", "--scenario", scenario, "--kind", "gain",
                                             "--robots", f.name, "--quiet"])
                    times.append(plan["took_ms"])
            finally:
                os.unlink(f.name)
            served = sum("unserved" not in r for r in plan["robots"])
            spacetime = sum(r.get("planned_by") == "space_time" for r in plan["robots"])
            print(f"| {label} | {access or '-'} | {m} | {served} | {spacetime} | "
                  f"{len(plan['timeline'])} | {statistics.median(times):.1f} |")


if __name__ == "__main__":
    main()
