#!/usr/bin/env python3
"""A user's session through the Python client that openapi-python-client generates from
openapi.yaml, against a running server, with no hand patch:

    python3 tests/clients/flow.py URL DIR_CONTAINING_irs_planner_client

register a scenario, a gain map, a path at "max", a sweep, coverage, a rate-map job polled to
done, a path with the power split, a cancelled job, an error decoded as the Problem type, the PNG
bytes, a placement search and its best map, and deleting what was created. Every request and response is also validated against the
contract with openapi-core. Prints "N passed, M failed"; exits 1 on any failure.
"""

import json
import pathlib
import sys
import time
from urllib.parse import parse_qs, urlparse

import httpx
import yaml
from openapi_core import Config, OpenAPI
from openapi_core.datatypes import RequestParameters
from werkzeug.datastructures import Headers, ImmutableMultiDict

URL = sys.argv[1].rstrip("/")
sys.path.insert(0, sys.argv[2])
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "support"))

import irs_testkit as kit  # noqa: E402

from irs_planner_client import Client  # noqa: E402
from irs_planner_client.api.default import (  # noqa: E402
    cancel_job, delete_scenario, get_coverage, get_job, get_map, get_map_image, get_placement,
    list_scenarios, place, plan_path, register_scenario, request_map, sweep)
from irs_planner_client.models import (  # noqa: E402
    Coverage, Job, JobState, MapBody, MapRequestById, MapSummary, PathAnswer, PathRequestByMapId,
    Placement, PlacementRequest, Problem, Scenario, ScenarioDocument, SweepAnswer,
    SweepRequestByMapId)

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
points = sweep.sync(client=client, body=SweepRequestByMapId.from_dict(
    {"map_id": gain_id, "start": [0.5, 0.5], "goal": [5.5, 3.5], "thresholds": [-80, -70, -60, -50]}))
check(isinstance(points, SweepAnswer) and len(points.points) == 4, "a sweep")
coverage = get_coverage.sync(client=client, map_id=gain_id, threshold="-60")
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
