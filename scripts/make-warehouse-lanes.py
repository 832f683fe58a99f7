#!/usr/bin/env python3
"""Writes scenarios/warehouse/lanes.geojson: the warehouse's route graph as a Nav2 Route
Server GeoJSON graph (nav2_route's loader rules: unique unsigned ids across nodes and edges,
directed edges, two features for a two-way lane), with the standard Python library only.

The lanes follow the aisles of scripts/make-warehouse.py:
* seven aisle rows along x, between and beside the racks (y = -16, -12, ..., 8), each with
  nodes at x = -24 (the west main aisle), -11 and 11 (mid-rack pick stations), 0 (the cross
  aisle) and 24 (the east main aisle);
* the west and east main aisles and the cross aisle joining the rows (north-south lanes);
* the north hall (y = 10) from the west aisle to x = 18, with a node before each office door
  (x = -26.4, -18.4, -10.4), and a lane through each door to a node inside the office (y = 15).
Every lane is two-way; edge metadata names the lane's aisle (`aisle`), as sites do.

Run it from the repository root: `python3 scripts/make-warehouse-lanes.py`; it rewrites the
file byte-for-byte identically.
"""

import json
from pathlib import Path

ROWS = [-16.0, -12.0, -8.0, -4.0, 0.0, 4.0, 8.0]
ROW_X = [-24.0, -11.0, 0.0, 11.0, 24.0]
HALL_Y = 10.0
HALL_X = [-26.4, -24.0, -18.4, -10.4, 0.0, 11.0, 18.0]
DOORS_X = [-26.4, -18.4, -10.4]
OFFICE_Y = 15.0

nodes = {}  # (x, y) -> id
features = []


def node(x, y, name):
    if (x, y) not in nodes:
        nodes[(x, y)] = len(nodes)
        features.append({
            "type": "Feature",
            "properties": {"id": nodes[(x, y)], "frame": "map", "metadata": {"name": name}},
            "geometry": {"type": "Point", "coordinates": [x, y]},
        })
    return nodes[(x, y)]


lanes = []  # (a, b, aisle)
for y in ROWS:
    for x in ROW_X:
        node(x, y, f"aisle {y:+.0f} at x {x:+.0f}")
    for x0, x1 in zip(ROW_X, ROW_X[1:]):
        lanes.append(((x0, y), (x1, y), f"row {y:+.0f}"))
for x in (-24.0, 0.0, 24.0):
    for y0, y1 in zip(ROWS, ROWS[1:]):
        lanes.append(((x, y0), (x, y1), f"column {x:+.0f}"))
for x in HALL_X:
    node(x, HALL_Y, f"hall at x {x:+.1f}")
for x0, x1 in zip(HALL_X, HALL_X[1:]):
    lanes.append(((x0, HALL_Y), (x1, HALL_Y), "hall"))
for x in (-24.0, 0.0, 11.0):
    lanes.append(((x, ROWS[-1]), (x, HALL_Y), f"column {x:+.0f}"))
for k, x in enumerate(DOORS_X):
    node(x, OFFICE_Y, f"office {k + 1}")
    lanes.append(((x, HALL_Y), (x, OFFICE_Y), f"office {k + 1} door"))

next_id = len(nodes)
for a, b, aisle in lanes:
    for start, end in ((a, b), (b, a)):
        features.append({
            "type": "Feature",
            "properties": {
                "id": next_id,
                "startid": nodes[start],
                "endid": nodes[end],
                "metadata": {"aisle": aisle},
            },
            "geometry": {"type": "MultiLineString", "coordinates": [[list(start), list(end)]]},
        })
        next_id += 1

graph = {"type": "FeatureCollection", "name": "warehouse lanes", "features": features}
out = Path(__file__).resolve().parent.parent / "scenarios" / "warehouse" / "lanes.geojson"
out.write_text(json.dumps(graph, indent=1) + "\n")
print(f"wrote {out}: {len(nodes)} nodes, {next_id - len(nodes)} edges")
