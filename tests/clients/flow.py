#!/usr/bin/env python3
"""A user's session through the Python client that openapi-python-client generates from
openapi.yaml, against a running server, with no hand patch:

    python3 tests/clients/flow.py URL [DIR_CONTAINING_irs_planner_client]

register a scenario, a gain map, a path at "max" in each threshold unit, a sweep, coverage, a
rate-map job polled to done, a path with the power split, a cancelled job, an error decoded as
the Problem type, the PNG bytes, a Nav2 mask archive, the .npy values, a Monte Carlo check run as
a job, a placement search and its best map, and deleting what was created. The client is
generated with the generator's default settings (no configuration file). Every request and response is also validated against the
contract with openapi-core. Prints "N passed, M failed"; exits 1 on any failure.
"""

import io
import json
import pathlib
import tarfile
import sys
import time
from urllib.parse import parse_qs, urlparse

import httpx
import numpy
import yaml
from openapi_core import Config, OpenAPI
from openapi_core.datatypes import RequestParameters
from werkzeug.datastructures import Headers, ImmutableMultiDict

URL = sys.argv[1].rstrip("/")
# The client as installed (pip install ./clients/python), or from a directory holding it.
sys.path[:0] = sys.argv[2:3]
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "support"))

import irs_testkit as kit  # noqa: E402

from irs_planner_client import Client  # noqa: E402
from irs_planner_client.api.default import (  # noqa: E402
    cancel_job, delete_scenario, get_check, get_coverage, get_job, get_map, get_map_image,
    get_map_values_npy, get_nav_2_mask, get_placement, list_scenarios, place, plan_fleet,
    plan_path, register_scenario, request_map, sweep)
from irs_planner_client.models import (  # noqa: E402
    Coverage, FleetPlan, FleetRequestByMap, Job, JobState, MapBody, MapRequestById, MapSummary,
    PathAnswer, PathRequestByMap, PathRequestByMapId, Placement, PlacementRequest, Problem, Reason,
    Scenario, ScenarioDocument, SweepAnswer, SweepRequestByMapId, Unit)

ROOT = pathlib.Path(__file__).resolve().parents[2]
# The contract, with the server under test as its server (openapi.yaml names the default one).
SPEC = yaml.safe_load((ROOT / "openapi.yaml").read_text())
SPEC["servers"] = [{"url": URL}]
# openapi-core parses application/json only; problem+json is JSON too (RFC 9457).
CONTRACT = OpenAPI.from_dict(SPEC, config=Config(
    extra_media_type_deserializers={"application/problem+json": json.loads}))


class HttpxRequest:
    """An httpx request as openapi-core's request protocol."""

    def __init__(self, request: httpx.Request):
        self.request = request
        url = urlparse(str(request.url))
        self.host_url = f"{url.scheme}://{url.netloc}"
        self.path = url.path
        self.method = request.method.lower()
        self.parameters = RequestParameters(
            query=ImmutableMultiDict(parse_qs(url.query)),
            header=Headers(dict(request.headers)),
            cookie=ImmutableMultiDict({}))
        self.body = request.content or None
        self.content_type = request.headers.get("content-type", "")


class HttpxResponse:
    """An httpx response as openapi-core's response protocol."""

    def __init__(self, response: httpx.Response):
        self.data = response.content
        self.status_code = response.status_code
        self.content_type = response.headers.get("content-type", "")
        self.headers = Headers(dict(response.headers))


CHECKS = kit.Checks()
check = CHECKS.check
exchanges = []


def record(response: httpx.Response):
    """httpx event hook: keep every exchange for contract validation."""
    response.read()
    exchanges.append(response)


client = Client(base_url=URL, timeout=httpx.Timeout(120.0),
                httpx_args={"event_hooks": {"response": [record]}})

# Register a scenario by content.
document = json.loads((ROOT / "scenarios" / "small-test.json").read_text())
document["name"] = "generated-client-flow"
document["ap"]["bandwidth_mhz"] = 20.0  # so that throughput (Mbit/s) is a unit it answers in
r = register_scenario.sync_detailed(client=client, body=Scenario.from_dict(document))
check(r.status_code == 201 and isinstance(r.parsed, ScenarioDocument), "register a scenario (201)", r.status_code)
scenario_id = r.parsed.id
listed = list_scenarios.sync(client=client)
check(any(s.id == scenario_id for s in listed.scenarios), "it is listed")

# A gain map, a path at "max", a sweep, coverage.
r = request_map.sync_detailed(client=client, body=MapRequestById.from_dict({"scenario_id": scenario_id, "kind": "gain"}))
check(r.status_code == 200 and isinstance(r.parsed, MapSummary),
      "a gain map is built while the request waits (200)", r.status_code)
gain_id = r.parsed.map_id
check(r.parsed.took_ms >= 0, "the summary says how long it took")
body = get_map.sync(client=client, map_id=gain_id)
check(isinstance(body, MapBody) and body.key.access is None and body.key.solver is None,
      "the map body decodes, access and solver null", type(body).__name__)
path = plan_path.sync(client=client, body=PathRequestByMapId.from_dict(
    {"map_id": gain_id, "start": [0.5, 0.5], "goal": [5.5, 3.5], "threshold": "max"}))
check(isinstance(path, PathAnswer) and path.feasible
      and path.threshold == path.max_feasible_threshold and len(path.waypoints) > 2,
      'a path at "max"', getattr(path, "distance_m", path))
# The same route at the largest feasible threshold in each unit: the threshold comes back in it.
symbols = {Unit.GAIN_DB: "dB", Unit.DBM: "dBm", Unit.SNR_DB: "dB SNR", Unit.BPS_HZ: "bit/s/Hz",
           Unit.MBPS: "Mbit/s"}
for unit, symbol in symbols.items():
    answer = plan_path.sync(client=client, body=PathRequestByMapId.from_dict(
        {"map_id": gain_id, "start": [0.5, 0.5], "goal": [5.5, 3.5], "threshold": "max",
         "unit": unit.value}))
    # One AP, so every unit orders the cells alike: the same route.
    check(isinstance(answer, PathAnswer) and answer.unit.value == symbol and answer.feasible
          and [(w.x, w.y) for w in answer.waypoints] == [(w.x, w.y) for w in path.waypoints],
          f"a path at max in {unit.value}", getattr(answer, "threshold", answer))
blocked = plan_path.sync(client=client, body=PathRequestByMapId.from_dict(
    {"map_id": gain_id, "start": [3.0, 2.0], "goal": [5.5, 3.5], "threshold": "max"}))
check(isinstance(blocked, PathAnswer) and not blocked.feasible and blocked.reason == Reason.START_OCCUPIED,
      "no path from inside the obstacle, and the reason is one enum", getattr(blocked, "reason", blocked))
points = sweep.sync(client=client, body=SweepRequestByMapId.from_dict(
    {"map_id": gain_id, "start": [0.5, 0.5], "goal": [5.5, 3.5], "thresholds": [-80, -70, -60, -50]}))
check(isinstance(points, SweepAnswer) and len(points.points) == 4, "a sweep")
coverage = get_coverage.sync(client=client, map_id=gain_id, threshold=-60.0)
check(isinstance(coverage, Coverage) and 0 <= coverage.coverage <= 1, "coverage")

# A rate map is a job: poll it to done, then plan with the power split.
r = request_map.sync_detailed(client=client, body=MapRequestById.from_dict(
    {"scenario_id": scenario_id, "kind": "rate", "access": "noma"}))
check(r.status_code == 202 and isinstance(r.parsed, Job), "a rate map starts a job (202)", r.status_code)
job = r.parsed
deadline = time.time() + 300
while job.state not in (JobState.DONE, JobState.FAILED, JobState.CANCELLED) and time.time() < deadline:
    time.sleep(0.2)
    job = get_job.sync(client=client, job_id=job.job_id)
check(job.state == JobState.DONE, "the job is polled to done", f"{job.state} {job.cells_done}/{job.cells_total}")
path = plan_path.sync(client=client, body=PathRequestByMapId.from_dict(
    {"map_id": job.map_id, "start": [0.5, 0.5], "goal": [5.5, 3.0], "threshold": "max"}))
check(isinstance(path, PathAnswer) and path.feasible
      and all(len(w.power_w) == 2 and len(w.decoding_order) == 2 for w in path.waypoints),
      "a rate-map path carries the power split and order per waypoint")

# A long build, cancelled.
multi = next(s.id for s in listed.scenarios if s.name == "paper-multi-user")
r = request_map.sync_detailed(client=client, body=MapRequestById.from_dict(
    {"scenario_id": multi, "kind": "rate", "access": "oma", "phases": 3}))
check(r.status_code == 202, "a long rate map starts a job", r.status_code)
cancelled = cancel_job.sync(client=client, job_id=r.parsed.job_id)
check(isinstance(cancelled, Job), "cancelling it is accepted", type(cancelled).__name__)
job = cancelled
deadline = time.time() + 60
while job.state != JobState.CANCELLED and time.time() < deadline:
    time.sleep(0.2)
    job = get_job.sync(client=client, job_id=job.job_id)
check(job.state == JobState.CANCELLED, "the job ends cancelled", job.state)

# An error answer decodes as the Problem type.
problem = get_map.sync(client=client, map_id="no-such-map")
check(isinstance(problem, Problem) and problem.status == 404 and problem.code.value == "not_found",
      "an error decodes as a Problem", problem)

# The picture.
r = get_map_image.sync_detailed(client=client, map_id=gain_id, start="0.5,0.5", goal="5.5,3.5")
check(r.status_code == 200 and r.content.startswith(b"\x89PNG\r\n\x1a\n"), "the PNG bytes", len(r.content))

# The exports: a Nav2 keep-out mask (a tar of its YAML and PGM) and the values as .npy.
mask = get_nav_2_mask.sync_detailed(client=client, map_id=gain_id, threshold=-60.0)
names = tarfile.open(fileobj=io.BytesIO(mask.content)).getnames() if mask.status_code == 200 else []
check(names == ["keepout.yaml", "keepout.pgm"], "the mask archive, as bytes", (mask.status_code, names))
npy = get_map_values_npy.sync_detailed(client=client, map_id=gain_id)
values = numpy.load(io.BytesIO(npy.content)) if npy.status_code == 200 else None
check(values is not None and values.shape == (len(body.values), len(body.values[0])),
      "the .npy values, as bytes", getattr(values, "shape", npy.status_code))

# A Monte Carlo check estimated over 2 s of CPU is a job; its answer is read at result_href.
paper = next(s.id for s in listed.scenarios if s.name == "paper-single-user")
r = plan_path.sync_detailed(client=client, body=PathRequestByMap.from_dict(
    {"map": {"scenario_id": paper, "kind": "gain"}, "start": [-10, 0], "goal": [10, 0],
     "threshold": -64, "monte_carlo_draws": 2500}))
check(r.status_code == 202 and isinstance(r.parsed, Job) and r.parsed.kind.value == "check",
      "a long Monte Carlo check is a job (202)", r.status_code)
job = r.parsed
deadline = time.time() + 120
while job.state not in (JobState.DONE, JobState.FAILED, JobState.CANCELLED) and time.time() < deadline:
    time.sleep(0.2)
    job = get_job.sync(client=client, job_id=job.job_id)
checked = get_check.sync(client=client, check_id=job.job_id)
check(job.result_href == f"/v1/checks/{job.job_id}" and isinstance(checked, PathAnswer)
      and checked.monte_carlo is not None and checked.monte_carlo.draws == 2500,
      "the checked path is read at result_href", checked)

# Where to mount the IRS: every metre of the south wall, ranked by coverage at −52 dB (the
# wall's middle covers 62.7 % of the floor, its west end 58.8 %); the best candidate's map
# answers at once, and the ranking reads back by id.
placement = place.sync(client=client, body=PlacementRequest.from_dict({
    "scenario_id": scenario_id,
    "candidates": {"walls": [{"from": [0, 0], "to": [6, 0]}], "step_m": 1.0},
    "objective": {"kind": "coverage", "threshold": -52}}))
check(isinstance(placement, Placement)
      and len(placement.candidates) + len(placement.rejected) == 7 and placement.map_kind.value == "gain"
      and placement.candidates[0].center[0] == 3.0
      and placement.candidates[0].score > placement.candidates[-1].score,
      "a placement ranks the wall's candidates", placement)
best = get_map.sync(client=client, map_id=placement.candidates[0].map_id)
check(isinstance(best, MapBody), "the best candidate's map is built", best)
again = get_placement.sync(client=client, placement_id=placement.placement_id)
check(isinstance(again, Placement)
      and [c.map_id for c in again.candidates] == [c.map_id for c in placement.candidates],
      "the ranking reads back by id", again)

# The hand-written helpers of the package (clients/python/irs_planner) over the same server.
import irs_planner  # noqa: E402

helper = irs_planner.connect(URL)
one_by_one = list(irs_planner.every(list_scenarios, helper, limit=1))
check([s.id for s in one_by_one] == [s.id for s in list_scenarios.sync(client=client).scenarios],
      "every page of a listing, one scenario a page", len(one_by_one))
grid = irs_planner.values(helper, gain_id, unit="dbm")
check(grid.shape == values.shape
      and abs(float(numpy.nanmax(grid)) - float(numpy.nanmax(values)) - 20.0) < 1e-3,
      "values as an array, in dBm (20 dBm of transmit power above the gain)", numpy.nanmax(grid))
r = plan_path.sync_detailed(client=helper, body=PathRequestByMap.from_dict(
    {"map": {"scenario_id": paper, "kind": "gain"}, "start": [-10, 0], "goal": [10, 0],
     "threshold": -64, "monte_carlo_draws": 2500, "seed": 2}))
answer = irs_planner.result(helper, r.parsed)
check(isinstance(answer, PathAnswer) and answer.monte_carlo.seed == 2, "a job's result, waited for", answer)
try:
    get_placement_answer = irs_planner.result(helper, Job.from_dict(dict(r.parsed.to_dict(), job_id="0" * 32)))
    check(False, "an unknown job is an error", get_placement_answer)
except irs_planner.ApiError as error:
    check(error.problem.status == 404, "an unknown job raises ApiError with the problem", error)

# A fleet plan asked for as a job whatever its size (Prefer: respond-async), its plan read by
# the helper at result_href.
r = plan_fleet.sync_detailed(client=helper, body=FleetRequestByMap.from_dict(
    {"map": {"scenario_id": paper, "kind": "gain"}, "robots": [
        {"name": "east", "start": [-10, 0], "goal": [10, 0], "threshold": -75},
        {"name": "west", "start": [10, -9], "goal": [-10, -9], "threshold": -80}]}),
    prefer="respond-async")
check(r.status_code == 202 and isinstance(r.parsed, Job) and r.parsed.kind.value == "fleet"
      and r.headers.get("preference-applied") == "respond-async",
      "a fleet plan asked for as a job (202, the preference applied)", r.status_code)
plan = irs_planner.result(helper, r.parsed)
check(isinstance(plan, FleetPlan) and plan.names == ["east", "west"] and plan.violations == []
      and all(robot.planned_by is not None for robot in plan.robots),
      "the fleet plan, read at its result_href", plan)

# Clean up.
r = delete_scenario.sync_detailed(client=client, scenario_id=scenario_id)
check(r.status_code == 204, "the scenario is deleted (204)", r.status_code)

# Every exchange against the contract.
invalid = []
for response in exchanges:
    request = HttpxRequest(response.request)
    try:
        CONTRACT.validate_request(request)
        CONTRACT.validate_response(request, HttpxResponse(response))
    except Exception as error:  # openapi-core raises one class per kind of violation
        invalid.append(f"{request.method.upper()} {request.path} {response.status_code}: {error!r}"[:400])
check(not invalid, f"all {len(exchanges)} requests and responses match openapi.yaml", "\n".join(invalid))

CHECKS.finish()
