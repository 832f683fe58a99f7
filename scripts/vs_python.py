#!/usr/bin/env python3
"""The Python half of scripts/vs-python.sh: the same two workloads as
examples/python_comparison.rs, in vectorised NumPy and in SciPy, timed in the same run and
checked against the Rust results.

  python3 scripts/vs_python.py RUST_GAIN_JSON RUST_MAZE_JSON RUST_PLACE_JSON OUT_DIR [REPEATS]

gain: the continuous closed form of docs/model.md §3 (eq. 12) on the paper floor at 2 cm, one
  array operation per step over the 1001 x 1001 cells. The slab test of each box is split into
  its per-axis parts, which depend on one grid coordinate each, so only the final max/min runs
  over the whole grid; NumPy's elementwise loops are single-threaded, so the Rust figure to
  compare with is the one-thread one. The values must agree to 1e-9 dB.
maze: scipy.sparse.csgraph.dijkstra from the maze's start over the same graph (free cells,
  8 neighbours, no diagonal past an occupied corner, Euclidean weights). Only the dijkstra
  call is timed (the graph is built once beforehand, as the Rust map is); it has no target, so
  it settles every cell, while the Rust search (jump point search, its per-query index built in
  the time) stops at the goal: in this maze the goal is the last corridor's end. At 2 cm
  (1001 x 1001) and at 10 cm (201 x 201). Distances must agree to 1e-9 m.
place: the IRS placement search of benches/maps.rs (164 wall poses of the paper floor at 0.5 m,
  each scored by the widest path's threshold from (-10, 0) to (10, 0)). The peer computes the
  direct link and the graph once, then per pose the surface's links over the grid in NumPy and
  the widest path as the path in a maximum spanning tree (scipy.sparse.csgraph). The Rust side
  is the whole search (candidates, ids, ranking). Scores must agree to 1e-9 dB.
"""
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

ROOT = Path(__file__).resolve().parent.parent
GRAZE_T = 1e-12  # src/geometry.rs: a segment that only touches a box is not blocked
ON_BOUNDARY_M = 1e-9  # src/geometry.rs: a cell centre on a footprint's edge is occupied


def timed(repeats, run):
    seconds = []
    for _ in range(repeats):
        t = time.perf_counter()
        result = run()
        seconds.append(time.perf_counter() - t)
    return statistics.median(seconds), min(seconds), result


def axis_slab(p, d, lo, hi):
    """Per-axis slab interval [t0, t1] of p + t d against [lo, hi] (arrays of one axis)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = (lo - p) / d, (hi - p) / d
    t0, t1 = np.minimum(a, b), np.maximum(a, b)
    # A segment parallel to the slab: inside the open slab it is unconstrained, else empty.
    parallel = d == 0
    inside = (p > lo) & (p < hi)
    t0 = np.where(parallel, np.where(inside, -np.inf, np.inf), t0)
    t1 = np.where(parallel, np.where(inside, np.inf, -np.inf), t1)
    return t0, t1


def blocked(source, xs, ys, z, boxes):
    """True where the segment source -> (x, y, z) passes through a box's interior."""
    out = np.zeros((xs.size, ys.size), dtype=bool)
    sx, sy, sz = source
    for lo, hi in boxes:
        x0, x1 = axis_slab(sx, xs - sx, lo[0], hi[0])
        y0, y1 = axis_slab(sy, ys - sy, lo[1], hi[1])
        z0, z1 = axis_slab(sz, np.array([z - sz]), lo[2], hi[2])
        low = np.maximum(np.maximum(x0[:, None], y0[None, :]), max(0.0, z0[0]))
        high = np.minimum(np.minimum(x1[:, None], y1[None, :]), min(1.0, z1[0]))
        out |= high - low > GRAZE_T
    return out


def path_loss_db(d2, los, f):
    """3GPP InF-SH (docs/model.md §2) from squared distances; d clamped to >= 1 m."""
    d = 0.5 * np.log10(np.maximum(d2, 1.0))
    pl_los = 31.84 + 21.50 * d + 19.0 * f
    return np.where(los, pl_los, np.maximum(pl_los, 32.4 + 23.0 * d + 20.0 * f))


class Floor:
    """A scenario's grid, boxes and link model: what the gain map and the placement peer share."""

    def __init__(self, s):
        room, res = s["room"], s["grid"]["resolution_m"]
        nx = round((room["x_max"] - room["x_min"]) / res) + 1
        ny = round((room["y_max"] - room["y_min"]) / res) + 1
        self.res, self.x_min, self.y_min = res, room["x_min"], room["y_min"]
        self.xs = room["x_min"] + np.arange(nx) * res
        self.ys = room["y_min"] + np.arange(ny) * res
        self.z = s["mru"]["antenna_height_m"]
        self.boxes = [
            (
                (o["center"][0] - o["size"][0] / 2, o["center"][1] - o["size"][1] / 2, 0.0),
                (o["center"][0] + o["size"][0] / 2, o["center"][1] + o["size"][1] / 2, o["height_m"]),
            )
            for o in s["obstacles"]
        ]
        self.f = math.log10(s["ap"]["carrier_ghz"])
        self.kappa = 10 ** (s["channel"]["rician_k_db"] / 10)
        self.ap = s["ap"]["position"]
        occupied = np.zeros((nx, ny), dtype=bool)
        for lo, hi in self.boxes:
            in_x = (self.xs >= lo[0] - ON_BOUNDARY_M) & (self.xs <= hi[0] + ON_BOUNDARY_M)
            in_y = (self.ys >= lo[1] - ON_BOUNDARY_M) & (self.ys <= hi[1] + ON_BOUNDARY_M)
            occupied |= in_x[:, None] & in_y[None, :]
        self.occupied = occupied

    def link(self, source):
        """(LoS amplitude, path gain, K) of every cell's link from `source`."""
        xs, ys, z = self.xs, self.ys, self.z
        d2 = (xs - source[0])[:, None] ** 2 + (ys - source[1])[None, :] ** 2 + (z - source[2]) ** 2
        los = ~blocked(source, xs, ys, z, self.boxes)
        gain = 10.0 ** (-path_loss_db(d2, los, self.f) / 10.0)
        k = np.where(los, self.kappa, 0.0)
        return np.sqrt(gain * k / (k + 1.0)), gain, k

    def direct(self):
        """The AP's direct link: (|h|, tau) per cell."""
        amplitude, gain, k = self.link(self.ap)
        return amplitude, gain / (k + 1.0)

    def surface(self, irs, c, n):
        """A coherent IRS at centre c with normal n: (||w||_1, tau_s) per cell (eq. 12, Lemma 1)."""
        ap, kappa = self.ap, self.kappa
        per_sub = irs["elements_per_sub"]
        subsurfaces = irs["nx_sub"] * irs["nz_sub"]
        elements = subsurfaces * per_sub
        # The AP-IRS link: one segment (the IRS centre as a 1 x 1 grid).
        d2 = sum((a - b) ** 2 for a, b in zip(ap, c))
        ap_los = not blocked(ap, np.array([c[0]]), np.array([c[1]]), c[2], self.boxes)[0, 0]
        ap_gain = 10.0 ** (-float(path_loss_db(np.array(d2), ap_los, self.f)) / 10.0)
        ka = kappa if ap_los else 0.0
        ap_amplitude = math.sqrt(ap_gain * ka / (ka + 1.0))
        faces_ap = sum((a - b) * m for a, b, m in zip(ap, c, n)) > 0
        served = (
            (self.xs - c[0])[:, None] * n[0] + (self.ys - c[1])[None, :] * n[1] + (self.z - c[2]) * n[2] > 0
        ) & faces_ap
        user_amplitude, user_gain, ku = self.link(c)
        l1 = np.where(served, subsurfaces * ap_amplitude * user_amplitude * per_sub, 0.0)
        tau = np.where(
            served, ap_gain * user_gain * (ku + ka + 1.0) * elements / ((ka + 1.0) * (ku + 1.0)), 0.0
        )
        return l1, tau

    def cell(self, p):
        """The flat index of the cell nearest to p (Grid::snap)."""
        i = round((p[0] - self.x_min) / self.res)
        j = round((p[1] - self.y_min) / self.res)
        return i * self.ys.size + j


def gain_map_numpy(s):
    floor = Floor(s)
    irs = s["irs"]
    direct_amplitude, tau = floor.direct()
    l1, tau_s = floor.surface(irs, irs["center"], irs["normal"])
    values = 10.0 * np.log10((direct_amplitude + l1) ** 2 + tau + tau_s)
    values[floor.occupied] = np.nan
    return values


def free_edges(free):
    """The free cells' undirected 8-neighbour edges (a diagonal only past two free sides), as
    flat index arrays (a, b), each edge once."""
    nx, ny = free.shape
    index = np.arange(nx * ny).reshape(nx, ny)
    a_list, b_list = [], []
    for di, dj in [(1, 0), (0, 1), (1, 1), (1, -1)]:
        a = index[: nx - di, max(0, -dj) : ny - max(0, dj)]
        b = index[di:, max(0, dj) : ny + min(0, dj) or None]
        ok = free.ravel()[a] & free.ravel()[b]
        if di and dj:
            # The two orthogonal neighbours (i + di, j) and (i, j + dj).
            ok &= free.ravel()[a + di * ny] & free.ravel()[a + dj]
        a_list.append(a[ok]), b_list.append(b[ok])
    return np.concatenate(a_list), np.concatenate(b_list)


def widest_threshold(values, edges, start, goal):
    """max over paths of the smallest cell value on the path (CellGraph::widest_path_threshold):
    the path between start and goal in a maximum spanning tree of the edges weighted by their
    narrower end. None when no path joins them."""
    a, b = edges
    width = np.minimum(values[a], values[b])
    # scipy finds minimum trees of positive weights: flip the widths into [1, ...).
    flipped = width.max() + 1.0 - width
    n = values.size
    tree = scipy.sparse.csgraph.minimum_spanning_tree(
        scipy.sparse.csr_matrix((flipped, (a, b)), shape=(n, n))
    )
    _, parent = scipy.sparse.csgraph.breadth_first_order(
        tree, start, directed=False, return_predecessors=True
    )
    if start == goal:
        return float(values[start])
    if parent[goal] < 0:
        return None
    narrowest, c = math.inf, goal
    while c != start:
        narrowest = min(narrowest, values[c], values[parent[c]])
        c = parent[c]
    return float(narrowest)


def place_numpy(s, poses, start, goal):
    """Scores of an IRS at each pose: the widest path's threshold on its gain map. The direct
    link and the graph are the same for every pose, so they are computed once (as the Rust
    search does); each pose costs its surface's links over the grid and a spanning tree."""
    floor = Floor(s)
    direct_amplitude, tau = floor.direct()
    free = ~floor.occupied
    edges = free_edges(free)
    start, goal = floor.cell(start), floor.cell(goal)
    scores = []
    for c, n in poses:
        l1, tau_s = floor.surface(s["irs"], c, n)
        values = (10.0 * np.log10((direct_amplitude + l1) ** 2 + tau + tau_s)).ravel()
        scores.append(widest_threshold(values, edges, start, goal) if free.ravel()[start] and free.ravel()[goal] else None)
    return scores


def maze_graph(free, resolution):
    """CSR adjacency of the free cells: 8 neighbours, a diagonal only past two free sides."""
    nx, ny = free.shape
    index = np.arange(nx * ny).reshape(nx, ny)
    rows, cols, weights = [], [], []

    def add(mask, di, dj, length):
        # Edges from (i, j) to (i + di, j + dj) where `mask` (over the overlapping window) holds.
        a = index[max(0, -di) : nx - max(0, di), max(0, -dj) : ny - max(0, dj)]
        b = index[max(0, di) : nx + min(0, di) or None, max(0, dj) : ny + min(0, dj) or None]
        rows.append(a[mask]), cols.append(b[mask])
        weights.append(np.full(int(mask.sum()), length * resolution))

    def window(di, dj):
        return free[max(0, di) : nx + min(0, di) or None, max(0, dj) : ny + min(0, dj) or None]

    def origin(di, dj):
        return free[max(0, -di) : nx - max(0, di), max(0, -dj) : ny - max(0, dj)]

    for di, dj in [(1, 0), (-1, 0), (0, 1), (0, -1)]:
        add(origin(di, dj) & window(di, dj), di, dj, 1.0)
    for di, dj in [(1, 1), (1, -1), (-1, 1), (-1, -1)]:
        # The two orthogonal neighbours (i + di, j) and (i, j + dj), aligned with the window.
        side_i = free[max(0, di) : nx + min(0, di) or None, max(0, -dj) : ny - max(0, dj)]
        side_j = free[max(0, -di) : nx - max(0, di), max(0, dj) : ny + min(0, dj) or None]
        add(origin(di, dj) & window(di, dj) & side_i & side_j, di, dj, math.sqrt(2.0))
    n = nx * ny
    return scipy.sparse.csr_matrix(
        (np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    )


def main():
    rust_gain = json.loads(Path(sys.argv[1]).read_text())
    rust_mazes = [json.loads(Path(a).read_text()) for a in sys.argv[2:4]]
    rust_place = json.loads(Path(sys.argv[4]).read_text())
    out = Path(sys.argv[5])
    repeats = int(sys.argv[6]) if len(sys.argv) > 6 else 7

    scenario = json.loads((ROOT / "scenarios/paper-single-user.json").read_text())
    scenario["grid"]["resolution_m"] = 0.02
    numpy_median, numpy_min, values = timed(repeats, lambda: gain_map_numpy(scenario))
    reference = np.load(out / "gain.npy")
    assert reference.shape == values.shape, (reference.shape, values.shape)
    assert np.array_equal(np.isnan(reference), np.isnan(values)), "occupied cells differ"
    free = ~np.isnan(values)
    worst_db = float(np.max(np.abs(reference[free] - values[free])))
    assert worst_db <= 1e-9, f"the NumPy map differs from the Rust map by {worst_db} dB"
    rust_one = rust_gain["one_thread_s"]["median"]
    rust_two = rust_gain["two_threads_s"]["median"]
    print(
        f"gain map 1001 x 1001, paper floor (median of {repeats}):\n"
        f"  numpy             {numpy_median * 1e3:8.1f} ms (min {numpy_min * 1e3:.1f})\n"
        f"  rust, one thread  {rust_one * 1e3:8.1f} ms (min {rust_gain['one_thread_s']['min'] * 1e3:.1f})"
        f"  -> {numpy_median / rust_one:.2f}x numpy\n"
        f"  rust, two threads {rust_two * 1e3:8.1f} ms (min {rust_gain['two_threads_s']['min'] * 1e3:.1f})"
        f"  -> {numpy_median / rust_two:.2f}x numpy\n"
        f"  largest |difference| {worst_db:.1e} dB over {int(free.sum())} free cells"
    )

    for rust_maze in rust_mazes:
        free_cells = np.load(out / rust_maze["free_file"]).astype(bool)
        graph = maze_graph(free_cells, rust_maze["resolution_m"])
        ny = free_cells.shape[1]
        start = rust_maze["start"][0] * ny + rust_maze["start"][1]
        goal = rust_maze["goal"][0] * ny + rust_maze["goal"][1]
        scipy_median, scipy_min, distances = timed(
            repeats, lambda: scipy.sparse.csgraph.dijkstra(graph, directed=True, indices=start)
        )
        difference = abs(float(distances[goal]) - rust_maze["distance_m"])
        assert difference <= 1e-9, (
            f"scipy's distance {distances[goal]} differs from the Rust one {rust_maze['distance_m']}"
        )
        rust_path = rust_maze["shortest_path_s"]["median"]
        print(
            f"maze {free_cells.shape[0]} x {ny}, 19 serpentine walls, "
            f"{rust_maze['waypoints']} waypoints, {rust_maze['distance_m']:.2f} m (median of {repeats}):\n"
            f"  scipy dijkstra    {scipy_median * 1e3:8.1f} ms (min {scipy_min * 1e3:.1f})\n"
            f"  rust jump points  {rust_path * 1e3:8.1f} ms (min {rust_maze['shortest_path_s']['min'] * 1e3:.1f})"
            f"  -> {scipy_median / rust_path:.2f}x scipy\n"
            f"  distances equal to {difference:.1e} m"
        )

    compare_placement(rust_place, repeats)


def compare_placement(rust, repeats):
    scenario = json.loads((ROOT / "scenarios/paper-single-user.json").read_text())
    poses = [(c["center"], c["normal"]) for c in rust["candidates"]]
    numpy_median, numpy_min, scores = timed(
        repeats, lambda: place_numpy(scenario, poses, rust["start"], rust["goal"])
    )
    worst_db = 0.0
    for candidate, score in zip(rust["candidates"], scores):
        theirs = candidate["score"]
        assert (theirs is None) == (score is None), (candidate, score)
        if score is not None:
            worst_db = max(worst_db, abs(theirs - score))
    assert worst_db <= 1e-9, f"the NumPy scores differ from the Rust ones by {worst_db} dB"
    rust_one, rust_two = rust["one_thread_s"], rust["two_threads_s"]
    print(
        f"placement, {len(poses)} IRS poses on the paper floor's walls, widest path "
        f"(median of {repeats}):\n"
        f"  numpy + scipy     {numpy_median * 1e3:8.1f} ms (min {numpy_min * 1e3:.1f})\n"
        f"  rust, one thread  {rust_one['median'] * 1e3:8.1f} ms (min {rust_one['min'] * 1e3:.1f})"
        f"  -> {numpy_median / rust_one['median']:.2f}x numpy\n"
        f"  rust, two threads {rust_two['median'] * 1e3:8.1f} ms (min {rust_two['min'] * 1e3:.1f})"
        f"  -> {numpy_median / rust_two['median']:.2f}x numpy\n"
        f"  largest |difference| {worst_db:.1e} dB over {len(poses)} scores"
    )


if __name__ == "__main__":
    main()
