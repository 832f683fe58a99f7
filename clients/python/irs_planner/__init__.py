"""A thin hand-written layer over `irs_planner_client`, the client generated from openapi.yaml:
only what every user would otherwise write again. Everything else is the generated client's
(`irs_planner_client.api.default`, `irs_planner_client.models`), which this module re-exports
nothing of.

    import irs_planner
    client = irs_planner.connect("http://127.0.0.1:8080")
    job = ...                      # a 202 answer's Job (a rate map, a placement, a long check,
                                   # a large fleet plan)
    answer = irs_planner.result(client, job)   # waits, then reads its result_href
    grid = irs_planner.values(client, map_id, unit="dbm")   # a numpy array (extra [numpy])
    for scenario in irs_planner.every(list_scenarios, client):   # every page
        ...
"""

from __future__ import annotations

import io
import time
from typing import Any, Callable, Iterator

from irs_planner_client import AuthenticatedClient, Client
from irs_planner_client.api.default import (
    get_check, get_fleet_plan, get_job, get_map, get_map_values_npy, get_placement)
from irs_planner_client.models import Job, JobKind, JobState, Problem, Unit
from irs_planner_client.types import UNSET

__all__ = ["ApiError", "JobEnded", "connect", "every", "result", "values", "wait"]


class ApiError(Exception):
    """The server answered a problem (RFC 9457): `problem` holds it (`code`, `detail`, `field`)."""

    def __init__(self, problem: Problem):
        super().__init__(f"{problem.status} {problem.code.value}: {problem.detail}")
        self.problem = problem


class JobEnded(Exception):
    """A job ended without its result: failed (`job.error` says why) or cancelled."""

    def __init__(self, job: Job):
        super().__init__(f"job {job.job_id} {job.state.value}: {job.error or 'no result'}")
        self.job = job


def connect(base_url: str = "http://127.0.0.1:8080", token: str | None = None,
            timeout: float = 120.0) -> Client | AuthenticatedClient:
    """A client of the server at `base_url`; with `token`, one that sends it as a bearer token
    (a server started with API tokens needs it for every POST and DELETE)."""
    import httpx

    if token is None:
        return Client(base_url=base_url, timeout=httpx.Timeout(timeout))
    return AuthenticatedClient(base_url=base_url, token=token, timeout=httpx.Timeout(timeout))


def _checked(answer: Any) -> Any:
    if isinstance(answer, Problem):
        raise ApiError(answer)
    if answer is None:
        raise ApiError(Problem.from_dict({
            "type": "about:blank", "code": "internal_error", "title": "No answer",
            "status": 0, "detail": "the server's answer was not one the contract lists"}))
    return answer


def wait(client: Client | AuthenticatedClient, job: Job, timeout: float = 600.0,
         interval: float = 0.2, progress: Callable[[Job], None] | None = None) -> Job:
    """Polls `job` until it is done and returns it; `progress` (if given) sees each poll.
    Raises `JobEnded` if it failed or was cancelled, `TimeoutError` after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        job = _checked(get_job.sync(client=client, job_id=job.job_id))
        if progress is not None:
            progress(job)
        if job.state == JobState.DONE:
            return job
        if job.state in (JobState.FAILED, JobState.CANCELLED):
            raise JobEnded(job)
        if time.monotonic() > deadline:
            raise TimeoutError(f"job {job.job_id} still {job.state.value} after {timeout} s")
        time.sleep(interval)


def result(client: Client | AuthenticatedClient, job: Job, **wait_args: Any) -> Any:
    """Waits for `job` ([`wait`]) and reads what its `result_href` serves: the map body of a map
    job, the ranking of a placement, the checked path of a Monte Carlo check, a fleet plan."""
    job = wait(client, job, **wait_args)
    if job.kind == JobKind.MAP:
        return _checked(get_map.sync(client=client, map_id=job.map_id))
    if job.kind == JobKind.PLACEMENT:
        return _checked(get_placement.sync(client=client, placement_id=job.job_id))
    if job.kind == JobKind.FLEET:
        return _checked(get_fleet_plan.sync(client=client, plan_id=job.job_id))
    return _checked(get_check.sync(client=client, check_id=job.job_id))


def values(client: Client | AuthenticatedClient, map_id: str, unit: str | None = None):
    """The map's values as a numpy array of shape (nx, ny) (`a[i, j]` is the cell at
    (x_min + iΔ, y_min + jΔ), NaN where occupied), in `unit` (default the map's own)."""
    import numpy

    answer = get_map_values_npy.sync_detailed(
        client=client, map_id=map_id, unit=UNSET if unit is None else Unit(unit))
    if answer.status_code != 200:
        _checked(answer.parsed)
    return numpy.load(io.BytesIO(answer.content))


def every(endpoint: Any, client: Client | AuthenticatedClient, **query: Any) -> Iterator[Any]:
    """Every item of a paginated listing (`list_scenarios`, `list_maps`, `list_jobs` from
    `irs_planner_client.api.default`), following `next_cursor` page by page."""
    cursor = UNSET
    while True:
        page = _checked(endpoint.sync(client=client, cursor=cursor, **query))
        field = next(f for f in ("scenarios", "maps", "jobs") if hasattr(page, f))
        yield from getattr(page, field)
        if not page.next_cursor:
            return
        cursor = page.next_cursor
