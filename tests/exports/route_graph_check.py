"""Every route graph the CLI and the server write loads by its consumer's own rules, read here
independently of the Rust reader (CI: .ci/run).

usage: route_graph_check.py BINARY SERVER_URL

Nav2 (nav2_route's GeoJSON loader, geojson_graph_file_loader.cpp): Point features are nodes,
LineString/MultiLineString features edges; `id`, `startid`, `endid` unsigned integers, ids unique
across nodes and edges, every `startid`/`endid` a node; `metadata` of booleans, numbers, strings,
objects and arrays of primitives only (no null); every number its scorers read as a float
(`penalty`, `speed_limit`) written with a decimal point, since an integer becomes an unsigned int
that `std::any_cast<float>` refuses. Open-RMF (rmf_fleet_adapter's parse_graph.cpp): `levels`, per
level `vertices` as [x, y, {options}] and `lanes` as [i, j, {options}] with i, j vertices of the
level, unique non-empty vertex names, `orientation_constraint` forward/backward, `speed_limit` a
number. Checked on: the warehouse's own lanes annotated at a threshold with penalties, roadmaps of
the paper floor and the warehouse in both formats (CLI and server, the same graph), and a route on
the lanes written as a VDA 5050 order whose nodes are the graph's nodes in driving order.
"""

import json
import re
import subprocess
import sys
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "support"))
import irs_testkit as kit  # noqa: E402

binary, base = sys.argv[1], sys.argv[2].rstrip("/")
CHECKS = kit.Checks(stop_on_failure=False)
check = CHECKS.check
PAPER = "scenarios/paper-single-user.json"
WAREHOUSE = "scenarios/warehouse/warehouse.json"
FLOAT_KEYS = ("penalty", "speed_limit")


def metadata_ok(value, path, problems):
    if not isinstance(value, dict):
        problems.append(f"{path}: not an object")
        return
    for key, v in value.items():
        here = f"{path}.{key}"
        if v is None:
            problems.append(f"{here}: null")
        elif isinstance(v, dict):
            metadata_ok(v, here, problems)
        elif isinstance(v, list):
            if any(isinstance(item, (dict, list)) or item is None for item in v):
                problems.append(f"{here}: an array of non-primitives")


def nav2_problems(text):
    """What nav2_route's loader would refuse or misread in a GeoJSON graph's text."""
    graph = json.loads(text)
    problems, nodes, ids = [], set(), set()
    features = graph.get("features", [])
    edges = []
    for k, f in enumerate(features):
        kind = f.get("geometry", {}).get("type")
        if kind not in ("Point", "LineString", "MultiLineString"):
            continue
        props = f.get("properties", {})
        for key in ("id",) + (() if kind == "Point" else ("startid", "endid")):
            v = props.get(key)
            if not (isinstance(v, int) and not isinstance(v, bool) and 0 <= v < 2**32):
                problems.append(f"features[{k}].{key}: {v!r} is not an unsigned int")
        if props.get("id") in ids:
            problems.append(f"features[{k}].id {props.get('id')} repeated")
        ids.add(props.get("id"))
        if "metadata" in props:
            metadata_ok(props["metadata"], f"features[{k}].metadata", problems)
        if kind == "Point":
            nodes.add(props.get("id"))
        else:
            edges.append((k, props.get("startid"), props.get("endid")))
    for k, start, end in edges:
        for which, node in (("startid", start), ("endid", end)):
            if node not in nodes:
                problems.append(f"features[{k}].{which} {node} is no node")
    # The scorers' float keys, as written: a digit run without '.' or an exponent is an integer.
    for key in FLOAT_KEYS:
        for m in re.finditer(rf'"{key}"\s*:\s*(-?[0-9.eE+-]+)', text):
            if not re.search(r"[.eE]", m.group(1)):
                problems.append(f"{key} written as an integer: {m.group(1)}")
    if not nodes or not edges:
        problems.append("no nodes or no edges")
    return problems, len(nodes), len(edges)


def rmf_problems(text):
    """What parse_graph.cpp would refuse in a nav graph's text (one level expected)."""
    graph = yaml.safe_load(text)
    problems = []
    levels = graph.get("levels")
    if not isinstance(levels, dict) or len(levels) != 1:
        return [f"levels: {type(levels).__name__} of {len(levels or {})}"], 0, 0
    (name, level), = levels.items()
    vertices, lanes = level.get("vertices", []), level.get("lanes", [])
    names = set()
    for k, v in enumerate(vertices):
        if not (isinstance(v, list) and len(v) == 3 and all(isinstance(c, (int, float)) for c in v[:2])
                and isinstance(v[2], dict)):
            problems.append(f"{name}.vertices[{k}]: {v!r}")
            continue
        label = v[2].get("name", "")
        if label and label in names:
            problems.append(f"{name}.vertices[{k}]: name {label!r} repeated")
        names.add(label)
    for k, lane in enumerate(lanes):
        ok = (isinstance(lane, list) and len(lane) == 3 and all(
            isinstance(i, int) and 0 <= i < len(vertices) for i in lane[:2]) and isinstance(lane[2], dict))
        if not ok:
            problems.append(f"{name}.lanes[{k}]: {str(lane)[:80]}")
            continue
        o = lane[2].get("orientation_constraint")
        if o is not None and o not in ("forward", "backward"):
            problems.append(f"{name}.lanes[{k}].orientation_constraint {o!r}")
        if "speed_limit" in lane[2] and not isinstance(lane[2]["speed_limit"], (int, float)):
            problems.append(f"{name}.lanes[{k}].speed_limit")
    return problems, len(vertices), len(lanes)


def loads(name, text, fmt):
    problems, nodes, edges = (nav2_problems if fmt == "nav2_geojson" else rmf_problems)(text)
    check(not problems and nodes > 0 and edges > 0,
          f"{name}: loads by its consumer's rules ({nodes} nodes, {edges} edges)", "; ".join(problems[:5]))
    return nodes, edges


def cli(args):
    run = subprocess.run([binary, *args, "--quiet", "--kind", "gain"], capture_output=True, text=True)
    check(run.returncode == 0, f"irs-planner {' '.join(args[:3])} exits 0", run.stderr[-300:])
    return run.stdout


def register(scenario):
    run = subprocess.run([binary, "scenario", "--scenario", scenario], capture_output=True, text=True)
    document = json.loads(run.stdout)
    sid = kit.post(base, "/v1/scenarios", document, raise_for_status=True).body["id"]
    return kit.post(base, "/v1/maps", {"scenario_id": sid, "kind": "gain"}, raise_for_status=True).body["map_id"]


def main():
    lanes = cli(["graph", "--scenario", WAREHOUSE, "--threshold=-72", "--penalty-band", "3", "--format", "graph"])
    nodes, edges = loads("warehouse lanes, annotated (CLI)", lanes, "nav2_geojson")
    check((nodes, edges) == (45, 116), f"the warehouse keeps its 45 nodes and 116 edges ({nodes}, {edges})")
    check('"penalty"' in lanes, "penalties within the band are written")
    warehouse = register(WAREHOUSE)
    served = kit.get(base, f"/v1/maps/{warehouse}/route-graph?threshold=-72&penalty_band=3&format=graph", parse="text")
    check(served.status == 200 and served.headers.get("content-type") == "application/geo+json",
          "the server writes the annotated lanes as application/geo+json", f"{served.status} {served.headers}")
    check(json.loads(served.body) == json.loads(lanes), "the server's annotated lanes are the CLI's")

    paper = register(PAPER)
    for scenario, map_id, spacing in ((PAPER, paper, "1"), (WAREHOUSE, warehouse, "2")):
        for fmt in ("nav2_geojson", "rmf_nav_graph"):
            name = f"roadmap of {Path(scenario).stem} at {spacing} m, {fmt}"
            text = cli(["roadmap", "--scenario", scenario, "--spacing-m", spacing, "--threshold=-75", "--format", fmt])
            loads(name + " (CLI)", text, fmt)
            answer = kit.get(base, f"/v1/maps/{map_id}/roadmap?spacing_m={spacing}&threshold=-75&format={fmt}", parse="text")
            failed = "" if answer.status == 200 else f"{answer.status} {str(answer.body)[:200]}"
            check(answer.status == 200, f"{name}: served", failed)
            same = (json.loads(answer.body) == json.loads(text)) if fmt == "nav2_geojson" else (
                yaml.safe_load(answer.body) == yaml.safe_load(text))
            check(same, f"{name}: the server's is the CLI's")

    # A route on the lanes as a VDA 5050 order: its nodes are graph nodes, in driving order.
    graph = json.loads(Path(WAREHOUSE).with_name("lanes.geojson").read_text())
    position = {tuple(f["geometry"]["coordinates"]) for f in graph["features"] if f["geometry"]["type"] == "Point"}
    order = json.loads(cli(["plan", "--scenario", WAREHOUSE, "--path-shape", "route_graph", "--start=-18.4,15",
                            "--goal=24,-16", "--threshold", "max", "--output", "vda5050-order"]))
    at = [(n["nodePosition"]["x"], n["nodePosition"]["y"]) for n in order["nodes"]]
    check(len(at) > 2 and all(p in position for p in at), f"the order's {len(at)} nodes are lane nodes", str(at[:4]))
    check(at[0] == (-18.4, 15.0) and at[-1] == (24.0, -16.0), "the order runs from office 2 to the south-east corner")


sys.exit(CHECKS.run(main))
