#!/usr/bin/env python3
"""The Python client that openapi-generator (the Java generator, from PyPI's openapi-generator-cli)
makes from openapi.yaml, against a running server, with no hand patch:

    python3 tests/clients/second_client.py URL DIR_CONTAINING_irs_planner_openapi

list scenarios, request a gain map, plan a path at "max", sweep, and decode an error.
Prints "N passed, M failed"; exits 1 on any failure.
"""

import pathlib
import sys

URL = sys.argv[1].rstrip("/")
sys.path.insert(0, sys.argv[2])
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "support"))

import irs_planner_openapi as api_client  # noqa: E402
import irs_testkit as kit  # noqa: E402

CHECKS = kit.Checks()
check = CHECKS.check

api = api_client.DefaultApi(api_client.ApiClient(api_client.Configuration(host=URL)))
scenarios = api.list_scenarios()
small = next(s.id for s in scenarios.scenarios if s.name == "small-test")
check(len(scenarios.scenarios) >= 3, "list scenarios")
summary = api.request_map(api_client.MapRequest(api_client.MapRequestById(scenario_id=small, kind="gain")))
check(summary.map_id and summary.key.kind == "gain", "request a gain map", summary.map_id)
path = api.plan_path(api_client.PathRequest(api_client.PathRequestByMapId(
    map_id=summary.map_id, start=[0.5, 0.5], goal=[5.5, 3.5], threshold=api_client.Threshold("max"))))
check(path.feasible and len(path.waypoints) > 2, 'plan a path at "max"', path.distance_m)
sweep = api.sweep(api_client.SweepRequest(api_client.SweepRequestByMapId(
    map_id=summary.map_id, start=[0.5, 0.5], goal=[5.5, 3.5], thresholds=[-70, -60])))
check(len(sweep.points) == 2, "a sweep")
try:
    api.get_map("no-such-map")
    check(False, "an unknown map is an error")
except api_client.ApiException as error:
    check(error.status == 404 and "not_found" in error.body, "an unknown map is a 404 problem", error.status)

CHECKS.finish()
