"""Every VDA 5050 order and zone set the CLI and the server write is valid against the
official schemas (CI: .ci/run).

usage: vda5050_check.py BINARY SERVER_URL

Orders for the paper's floor (grid and any-angle routes, margins that release all, part or
only the start) and the warehouse are validated against tests/data/vda5050/order.schema
(VDA5050/VDA5050, JSON Schema draft 2020-12) with formats checked; the timestamp is the
specification's YYYY-MM-DDTHH:mm:ss.fffZ. Zone sets of both floors, with and without penalty
zones, are validated against zoneSet.schema. The server's messages equal the CLI's but for the
timestamp, and its refusals name the field.
"""

import json
import re
import subprocess
import sys
from pathlib import Path

import jsonschema

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "support"))
import irs_testkit as kit  # noqa: E402

binary, base = sys.argv[1], sys.argv[2].rstrip("/")
ROOT = Path(__file__).resolve().parents[2]


def validator(name):
    schema = json.loads((ROOT / "tests/data/vda5050" / name).read_text())
    return jsonschema.Draft202012Validator(schema, format_checker=jsonschema.Draft202012Validator.FORMAT_CHECKER)


VALIDATOR = validator("order.schema")
ZONES_VALIDATOR = validator("zoneSet.schema")
STAMP = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z$")
MEDIA = "application/vnd.vda5050.order+json"
CHECKS = kit.Checks(stop_on_failure=False)
check = CHECKS.check

PAPER = "scenarios/paper-single-user.json"
WAREHOUSE = "scenarios/warehouse/warehouse.json"
CASES = [
    ("paper, grid, max", PAPER, ["--start=-8,-8", "--goal=8,6", "--threshold", "max"]),
    ("paper, any angle, -75 dB, margin 10", PAPER,
     ["--start=-8,-8", "--goal=8,6", "--threshold=-75", "--path-shape", "any_angle", "--release-margin", "10"]),
    ("paper, any angle, -75 dB, margin 20", PAPER,
     ["--start=-8,-8", "--goal=8,6", "--threshold=-75", "--path-shape", "any_angle", "--release-margin", "20"]),
    ("paper, dBm, ids given", PAPER,
     ["--start=-9,9", "--goal=9,-9", "--threshold", "max", "--unit", "dbm", "--order-id", "o-17",
      "--order-update-id", "3", "--header-id", "42", "--manufacturer", "acme", "--serial-number", "r2",
      "--vda-map-id", "hall-1"]),
    ("warehouse, any angle", WAREHOUSE, ["--start=1,1", "--goal=28,18", "--threshold", "max", "--path-shape", "any_angle"]),
]


def valid(order, name, against=VALIDATOR, schema="order.schema"):
    errors = sorted(against.iter_errors(order), key=lambda e: list(e.path))
    check(not errors, f"{name}: valid against {schema}", "; ".join(
        f"{'/'.join(map(str, e.path))}: {e.message}" for e in errors[:5]))
    check(bool(STAMP.match(order.get("timestamp", ""))), f"{name}: timestamp {order.get('timestamp')!r} as §7.2 writes it")


def cli_order(scenario, args):
    run = subprocess.run([binary, "plan", "--quiet", "--scenario", scenario, "--kind", "gain",
                          "--output", "vda5050-order", *args], capture_output=True, text=True)
    check(run.returncode == 0, f"plan {' '.join(args)} exits 0", run.stderr[-300:])
    return json.loads(run.stdout)


def main():
    released = set()
    for name, scenario, args in CASES:
        order = cli_order(scenario, args)
        valid(order, name)
        released.add(sum(n["released"] for n in order["nodes"]) == len(order["nodes"]))
    check(released == {True, False}, "the cases include whole and partly released orders")
    # The schema can fail: an order whose node lacks its actions, or whose sequenceId is
    # negative, is refused.
    broken = json.loads(json.dumps(order))
    del broken["nodes"][0]["actions"]
    broken["edges"][0]["sequenceId"] = -1
    check(len(list(VALIDATOR.iter_errors(broken))) == 2, "the schema refuses a broken order (control)")

    # The server writes the same order (but for its timestamp) for the same query.
    document = subprocess.run([binary, "scenario", "--scenario", PAPER], check=True, capture_output=True).stdout
    scenario_id = kit.post(base, "/v1/scenarios", document, raise_for_status=True).body["id"]
    map_id = kit.post(base, "/v1/maps", {"scenario_id": scenario_id, "kind": "gain"}, raise_for_status=True).body["map_id"]
    query = {"map_id": map_id, "start": [-8, -8], "goal": [8, 6], "threshold": -75, "path_shape": "any_angle",
             "order": {"release_margin": 20, "manufacturer": "acme", "serial_number": "r1"}}
    served = kit.post(base, "/v1/paths", query, headers={"accept": MEDIA})
    check(served.status == 200, "POST /v1/paths with Accept: the order", str(served.body)[:300])
    check(served.headers.get("content-type") == MEDIA, f"content-type {served.headers.get('content-type')}")
    valid(served.body, "the server's order")
    cli = cli_order(PAPER, ["--start=-8,-8", "--goal=8,6", "--threshold=-75", "--path-shape", "any_angle",
                            "--release-margin", "20", "--manufacturer", "acme", "--serial-number", "r1"])
    same = {k: v for k, v in served.body.items() if k != "timestamp"} == {k: v for k, v in cli.items() if k != "timestamp"}
    check(same, "the server's order is the CLI's but for the timestamp")

    refusals = [
        ("order without the order's Accept", dict(query), {}, "order"),
        ("an unknown order field", dict(query, order={"speed": 1}), {"accept": MEDIA}, "order.speed"),
        ("a negative margin", dict(query, order={"release_margin": -1}), {"accept": MEDIA}, "order.release_margin"),
        ("no path at the threshold", dict(query, threshold=100, order={}), {"accept": MEDIA}, "threshold"),
    ]
    for name, body, headers, field in refusals:
        answer = kit.post(base, "/v1/paths", body, headers=headers)
        mismatch = kit.problem_mismatch(answer, 422, field=field)
        check(not mismatch, f"{name}: 422 naming {field}", mismatch)


ZONE_CASES = [
    ("paper, blocked only", PAPER, ["--threshold=-66"]),
    ("paper, penalties", PAPER, ["--threshold=-66", "--penalty-band", "6", "--penalty-levels", "3",
                                 "--vda-map-id", "hall-1", "--manufacturer", "acme", "--serial-number", "r2",
                                 "--header-id", "7", "--zone-set-id", "zs-1"]),
    ("warehouse, penalties", WAREHOUSE, ["--threshold=-70", "--penalty-band", "6"]),
]


def cli_zones(scenario, args):
    run = subprocess.run([binary, "zones", "--quiet", "--scenario", scenario, "--kind", "gain", *args],
                         capture_output=True, text=True)
    check(run.returncode == 0, f"zones {' '.join(args)} exits 0", run.stderr[-300:])
    return json.loads(run.stdout)


def zones_main():
    for name, scenario, args in ZONE_CASES:
        message = cli_zones(scenario, args)
        valid(message, name, ZONES_VALIDATOR, "zoneSet.schema")
        zones = message["zoneSet"]["zones"]
        kinds = {z["zoneType"] for z in zones}
        check("BLOCKED" in kinds and (("PENALTY" in kinds) == ("--penalty-band" in args)),
              f"{name}: {len(zones)} zones of {sorted(kinds)}, {sum(len(z['vertices']) for z in zones)} vertices")
    broken = json.loads(json.dumps(message))
    broken["zoneSet"]["zones"][0]["vertices"] = broken["zoneSet"]["zones"][0]["vertices"][:2]
    broken["zoneSet"]["zones"][-1].pop("penaltyFactor")
    check(len(list(ZONES_VALIDATOR.iter_errors(broken))) == 2, "the schema refuses a broken zone set (control)")

    document = subprocess.run([binary, "scenario", "--scenario", PAPER], check=True, capture_output=True).stdout
    scenario_id = kit.post(base, "/v1/scenarios", document, raise_for_status=True).body["id"]
    map_id = kit.post(base, "/v1/maps", {"scenario_id": scenario_id, "kind": "gain"}, raise_for_status=True).body["map_id"]
    query = "threshold=-66&penalty_band=6&penalty_levels=3&vda_map_id=hall-1&manufacturer=acme&serial_number=r2&header_id=7&zone_set_id=zs-1"
    served = kit.get(base, f"/v1/maps/{map_id}/zone-set?{query}")
    check(served.status == 200, "GET /v1/maps/{id}/zone-set", str(served.body)[:300])
    check(served.headers.get("content-type") == "application/vnd.vda5050.zone-set+json",
          f"content-type {served.headers.get('content-type')}")
    valid(served.body, "the server's zone set", ZONES_VALIDATOR, "zoneSet.schema")
    cli = cli_zones(PAPER, ZONE_CASES[1][2])
    same = {k: v for k, v in served.body.items() if k != "timestamp"} == {k: v for k, v in cli.items() if k != "timestamp"}
    check(same, "the server's zone set is the CLI's but for the timestamp")
    for name, q, field in [
        ("levels without a band", "threshold=-66&penalty_levels=3", "penalty_levels"),
        ("a band of 0", "threshold=-66&penalty_band=0", "penalty_band"),
        ("11 levels", "threshold=-66&penalty_band=3&penalty_levels=11", "penalty_levels"),
        ("no threshold", "penalty_band=3", "threshold"),
        ("a map id of 201 characters", "threshold=-66&vda_map_id=" + "m" * 201, "vda_map_id"),
        ("an unknown parameter", "threshold=-66&speed=1", "speed"),
    ]:
        answer = kit.get(base, f"/v1/maps/{map_id}/zone-set?{q}")
        mismatch = kit.problem_mismatch(answer, 422, field=field)
        check(not mismatch, f"zone set, {name}: 422 naming {field}", mismatch)


def both():
    main()
    zones_main()


sys.exit(CHECKS.run(both))
