#!/usr/bin/env python3
"""The Python client that openapi-generator (the Java generator, from PyPI's openapi-generator-cli)
makes from openapi.yaml, against a running server, with no hand patch:

    python3 tests/clients/second_client.py URL DIR_CONTAINING_irs_planner_openapi

register a scenario, list scenarios, request a gain map, plan a path at "max" in each threshold
unit, sweep, read the PNG, the Nav2 mask archive and the .npy values as bytes, poll a rate-map job
to done, rank placements, run a Monte Carlo check as a job and read its answer, and decode an
error. Generated with the generator's default settings (the contract
validates without --skip-validate-spec).
Prints "N passed, M failed"; exits 1 on any failure.
"""

import io
import json
import pathlib
import sys
import tarfile
import time

import numpy

URL = sys.argv[1].rstrip("/")
sys.path.insert(0, sys.argv[2])
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "support"))

import irs_planner_openapi as api_client  # noqa: E402
import irs_testkit as kit  # noqa: E402

CHECKS = kit.Checks()
check = CHECKS.check

api = api_client.DefaultApi(api_client.ApiClient(api_client.Configuration(host=URL)))
document = json.loads((pathlib.Path(__file__).resolve().parents[2] / "scenarios" / "small-test.json").read_text())
document["name"] = "second-client"
registered = api.register_scenario(api_client.Scenario.from_dict(document))
small = registered.id
scenarios = api.list_scenarios()
check(any(s.id == small for s in scenarios.scenarios), "register a scenario", small)
check(len(scenarios.scenarios) >= 3, "list scenarios")
summary = api.request_map(api_client.MapRequest(api_client.MapRequestById(scenario_id=small, kind="gain")))
check(summary.map_id and summary.key.kind == "gain", "request a gain map", summary.map_id)
path = api.plan_path(api_client.PathRequest(api_client.PathRequestByMapId(
    map_id=summary.map_id, start=[0.5, 0.5], goal=[5.5, 3.5], threshold=api_client.Threshold("max"))))
check(path.feasible and len(path.waypoints) > 2, 'plan a path at "max"', path.distance_m)
for unit, symbol in [("gain_db", "dB"), ("dbm", "dBm"), ("snr_db", "dB SNR"), ("bps_hz", "bit/s/Hz")]:
    answer = api.plan_path(api_client.PathRequest(api_client.PathRequestByMapId(
        map_id=summary.map_id, start=[0.5, 0.5], goal=[5.5, 3.5], threshold=api_client.Threshold("max"),
        unit=api_client.Unit(unit))))
    check(answer.unit == symbol and [(w.x, w.y) for w in answer.waypoints] == [(w.x, w.y) for w in path.waypoints],
          f"a path at max in {unit}", answer.threshold)
sweep = api.sweep(api_client.SweepRequest(api_client.SweepRequestByMapId(
    map_id=summary.map_id, start=[0.5, 0.5], goal=[5.5, 3.5], thresholds=[-70, -60])))
check(len(sweep.points) == 2, "a sweep")
png = api.get_map_image(summary.map_id)
check(bytes(png).startswith(b"\x89PNG\r\n\x1a\n"), "the PNG, as bytes", len(png))
mask = api.get_nav2_mask(summary.map_id, threshold=-60)
names = tarfile.open(fileobj=io.BytesIO(bytes(mask))).getnames()
check(names == ["keepout.yaml", "keepout.pgm"], "the Nav2 mask archive, as bytes", names)
values = numpy.load(io.BytesIO(bytes(api.get_map_values_npy(summary.map_id))))
check(values.ndim == 2 and values.dtype == numpy.float32, "the .npy values, as bytes", values.shape)
rate = api.request_map_with_http_info(api_client.MapRequest(api_client.MapRequestById(
    scenario_id=small, kind="rate", access="noma")))
check(rate.status_code == 202 and rate.data.kind == "map", "a rate map is a job (202)", rate.status_code)
deadline = time.time() + 300
while api.get_job(rate.data.job_id).state not in ("done", "failed", "cancelled") and time.time() < deadline:
    time.sleep(0.2)
check(api.get_job(rate.data.job_id).state == "done", "the rate-map job is polled to done")
ranking = api.place(api_client.PlacementRequest.from_dict({
    "scenario_id": small, "candidates": {"walls": [{"from": [0, 0], "to": [6, 0]}], "step_m": 1.0},
    "objective": {"kind": "coverage", "threshold": -52}}))
check(len(ranking.candidates) + len(ranking.rejected) == 7 and ranking.candidates[0].center[0] == 3.0,
      "placements ranked", ranking.candidates[0].center)
paper = next(s.id for s in scenarios.scenarios if s.name == "paper-single-user")
response = api.plan_path_with_http_info(api_client.PathRequest(api_client.PathRequestByMap(
    map=api_client.MapRequest(api_client.MapRequestById(scenario_id=paper, kind="gain")),
    start=[-10, 0], goal=[10, 0], threshold=api_client.Threshold(-64), monte_carlo_draws=2500)))
check(response.status_code == 202, "a long Monte Carlo check is a job (202)", response.status_code)
job_id = response.data.job_id
deadline = time.time() + 120
while api.get_job(job_id).state not in ("done", "failed", "cancelled") and time.time() < deadline:
    time.sleep(0.2)
checked = api.get_check(job_id)
check(checked.monte_carlo is not None and checked.monte_carlo.draws == 2500,
      "the checked path is read by its job id", job_id)
try:
    api.get_map("no-such-map")
    check(False, "an unknown map is an error")
except api_client.ApiException as error:
    check(error.status == 404 and "not_found" in error.body, "an unknown map is a 404 problem", error.status)
api.delete_scenario(small)

CHECKS.finish()
