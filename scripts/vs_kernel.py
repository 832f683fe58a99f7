#!/usr/bin/env python3
"""The service's gain map against the minimum-work C kernel of the same closed form
(scripts/min_kernel.c), on the paper's single-user floor (issue 35, item 2).

Usage: vs_kernel.py BINARY [RESOLUTION_M=0.02] [RUNS=5]

Prints, each the best of RUNS interleaved runs: the kernel's loop on one thread; the build
alone on one thread (`took_ms` of `irs-planner map` under RAYON_NUM_THREADS=1); the whole
`irs-planner export` process (build, then the values as map.npy and the two Nav2 masks: a
binary output) and the whole `irs-planner map` process (the JSON body), both on one thread and
on all cores; and each against the kernel. Checks first that the two agree in every cell
(float32 .npy against float64: within 1e-4 dB, NaN on the same cells).
"""

import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    binary = os.path.abspath(sys.argv[1])
    resolution = float(sys.argv[2]) if len(sys.argv) > 2 else 0.02
    runs = int(sys.argv[3]) if len(sys.argv) > 3 else 5
    work = tempfile.mkdtemp(prefix="irs-vs-kernel-")
    kernel = os.path.join(work, "min_kernel")
    # The flags of min_kernel.c's header (why the 512-bit preference: there).
    subprocess.run(["cc", "-O3", "-march=native", "-mprefer-vector-width=512", "-ffast-math",
                    "-o", kernel, os.path.join(ROOT, "scripts", "min_kernel.c"), "-lm"],
                   check=True)

    with open(os.path.join(ROOT, "scenarios", "paper-single-user.json")) as f:
        s = json.load(f)
    s["grid"]["resolution_m"] = resolution
    scenario = os.path.join(work, "scenario.json")
    with open(scenario, "w") as f:
        json.dump(s, f)
    room, irs = s["room"], s["irs"]
    nx = round((room["x_max"] - room["x_min"]) / resolution) + 1
    ny = round((room["y_max"] - room["y_min"]) / resolution) + 1
    boxes = []
    for o in s["obstacles"]:
        (cx, cy), (sx, sy) = o["center"], o["size"]
        boxes += [cx - sx / 2, cy - sy / 2, 0.0, cx + sx / 2, cy + sy / 2, o["height_m"]]
    raw = os.path.join(work, "kernel.f64")
    kernel_args = [kernel, raw, nx, ny, room["x_min"], room["y_min"], resolution,
                   s["mru"]["antenna_height_m"], *s["ap"]["position"], *irs["center"],
                   *irs["normal"], irs["nx_sub"] * irs["nz_sub"], irs["elements_per_sub"],
                   s["ap"]["carrier_ghz"], s["channel"]["rician_k_db"], *boxes]
    kernel_args = [str(a) for a in kernel_args]

    one = dict(os.environ, RAYON_NUM_THREADS="1")
    out = os.path.join(work, "export")
    gain = ["--scenario", scenario, "--kind", "gain", "--quiet"]
    export = [binary, "export", *gain, "--threshold", "-70", "--out", out]
    build = [binary, "map", *gain]

    # Agreement first.
    subprocess.run(kernel_args, check=True, capture_output=True)
    subprocess.run(export, check=True, env=one)
    ours = np.load(os.path.join(out, "map.npy")).astype(np.float64)
    theirs = np.fromfile(raw, dtype=np.float64).reshape(nx, ny)
    if not np.array_equal(np.isnan(ours), np.isnan(theirs)):
        sys.exit("the occupied cells differ")
    difference = float(np.nanmax(np.abs(ours - theirs)))
    if difference > 1e-4:
        sys.exit(f"the values differ by up to {difference} dB")

    def wall(command, env):
        started = time.perf_counter()
        subprocess.run(command, check=True, env=env, stdout=subprocess.DEVNULL)
        return time.perf_counter() - started

    figures = {k: [] for k in ("kernel", "build", "export 1", "export", "map 1", "map")}
    for _ in range(runs):
        figures["kernel"].append(float(subprocess.run(kernel_args, check=True, capture_output=True,
                                                      text=True).stdout))
        body = subprocess.run(build, check=True, env=one, capture_output=True, text=True).stdout
        figures["build"].append(json.loads(body)["took_ms"] / 1000)
        figures["export 1"].append(wall(export, one))
        figures["export"].append(wall(export, os.environ))
        figures["map 1"].append(wall(build, one))
        figures["map"].append(wall(build, os.environ))
    floor = min(figures["kernel"])
    print(f"paper floor at {resolution} m ({nx} x {ny} cells); agreement within {difference:.1e} dB")
    labels = {
        "kernel": "C kernel, one thread",
        "build": "build (took_ms), one thread",
        "export 1": "whole export process (.npy + masks), one thread",
        "export": "whole export process, all cores",
        "map 1": "whole map process (JSON), one thread",
        "map": "whole map process (JSON), all cores",
    }
    for key, label in labels.items():
        best = min(figures[key])
        print(f"{label:50s} {best * 1000:8.1f} ms  {best / floor:5.2f}x the kernel")


if __name__ == "__main__":
    main()
