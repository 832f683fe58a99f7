#!/usr/bin/env python3
"""Reliability suite: what an anonymous client or a heavy user does to a release server, each
case against its own server on a loopback port, with the figure it measured in the log.

Usage: suite.py BINARY [CASE ...]   (cases: overflow cache lost-work starvation slow-loris
slow-readers ownership shutdown files; default all). Exits 1 on the first failed expectation. Bounded: every
case stops by itself (about 90 s in all on two cores); traffic goes to 127.0.0.1 only.
"""

import json
import os
import pathlib
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "support"))
import irs_testkit as kit  # noqa: E402
from irs_testkit import problem_mismatch, scenario  # noqa: E402

BINARY = None


class Server(kit.Server):
    """`irs-planner serve` on a free loopback port with extra flags (no scenario preloaded but
    the built-in ones); its requests time out after 120 s unless told."""

    def __init__(self, *flags):
        empty = tempfile.mkdtemp(prefix="irs-reliability-")
        super().__init__(BINARY, "--scenarios", empty, *flags, timeout=120)

    def timed_get(self, path):
        started = time.perf_counter()
        status, _, _ = self.get(path, timeout=10)
        return status, (time.perf_counter() - started) * 1000

    def rss_mb(self, peak=False):
        key = "VmHWM" if peak else "VmRSS"
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith(key):
                    return int(line.split()[1]) / 1024
        return 0.0

    def scenario_id(self, name):
        return kit.scenario_id(self.base, name)


def expect(condition, message):
    if not condition:
        raise AssertionError(message)


def figure(case, text):
    print(f"[{case}] {text}", flush=True)


# ------------------------------------------------------------------------------------ cases


def overflow():
    """Sizes that wrapped or were taken on trust: each refused with 422, nothing allocated."""
    server = Server()
    try:
        def irs(**fields):
            return scenario("small-test", lambda d: d["irs"].update(fields))

        def room(**fields):
            return scenario("small-test", lambda d: d["room"].update(fields))

        cases = {
            "nx_sub = nz_sub = 2^32": irs(nx_sub=2**32, nz_sub=2**32),
            "nz_sub = 2^63": irs(nz_sub=2**63),
            "elements_per_sub = 2^63 + 1": irs(elements_per_sub=2**63 + 1),
            "resolution larger than the room": scenario(
                "small-test", lambda d: d["grid"].update(resolution_m=100.0)),
            "20 km × 0.5 m corridor": scenario("small-test", lambda d: (
                d["room"].update(x_max=20000.0, y_max=0.5), d["grid"].update(resolution_m=0.5))),
            "room at 1e300 m": room(x_min=-1e300),
            "a 3-coordinate point": scenario("small-test", lambda d: d["ap"].update(position=[1, 2, 3, 4])),
            "a 1 MB name": scenario("small-test", lambda d: d.update(name="n" * 1_000_000)),
        }
        statuses = {}
        for what, doc in cases.items():
            answer = server.post("/v1/scenarios", doc)
            statuses[what] = answer.status
            wrong = problem_mismatch(answer, 422, field=True)
            expect(not wrong, f"{what}: {wrong}")
        answer = server.post(
            "/v1/paths", {"map_id": "x", "start": [1, 2, 3], "goal": [1, 2], "threshold": 0})
        wrong = problem_mismatch(answer, 422, field="start")
        expect(not wrong, f"3-coordinate start: {wrong}")
        # Work above the budget is refused before it starts.
        heavy = scenario("paper-single-user", lambda d: (
            d["irs"].update(grouping="elements", elements_per_sub=3000),
            d["grid"].update(resolution_m=0.02)))
        answer = server.post("/v1/maps", {"scenario": heavy, "kind": "gain"})
        wrong = problem_mismatch(answer, 422, code="limit_exceeded")
        expect(not wrong, f"budget: {wrong}")
        body = answer.body
        expect(server.get("/healthz")[0] == 200, "the server died")
        figure("overflow", f"{len(cases) + 2} hostile inputs → 422 naming the field; "
               f"server alive, RSS {server.rss_mb(peak=True):.0f} MB peak "
               f"(budget refusal: {body['detail'][:70]}…)")
    finally:
        server.stop()


def cache():
    """Maps of M = 200 000 elements each hold 6.4 MB of channel model: the cache weighs it."""
    budget_mb = 64
    server = Server("--cache-mb", str(budget_mb))
    try:
        baseline = server.rss_mb()
        maps = 30
        for k in range(maps):
            doc = scenario("small-test", lambda d: (
                d.update(name=f"m200k-{k}"),
                d["irs"].update(nx_sub=20, nz_sub=10, elements_per_sub=1000, grouping="elements")))
            status, body, _ = server.post("/v1/maps", {"scenario": doc, "kind": "gain"})
            expect(status == 200, f"map {k}: {status} {body}")
        gauge = server.metric("irs_map_cache_bytes") / 2**20
        rss = server.rss_mb()
        slack = 64
        expect(gauge <= budget_mb, f"cache gauge {gauge:.1f} MB above the budget")
        expect(rss <= baseline + budget_mb + slack,
               f"RSS {rss:.0f} MB above baseline {baseline:.0f} + budget {budget_mb} + slack {slack}")
        figure("cache", f"{maps} maps of M = 200 000 (≈ {maps * 6.4:.0f} MB unweighed) with "
               f"--cache-mb {budget_mb}: cache gauge {gauge:.1f} MB, RSS {rss:.0f} MB "
               f"(baseline {baseline:.0f} MB, limit baseline + {budget_mb} + {slack} MB slack)")
    finally:
        server.stop()


def lost_work():
    """A full cache never costs a request its map, and a done job's map is there."""
    server = Server("--cache-mb", "2")
    try:
        # 1.5 MB maps in a 2 MB cache: each build evicts the one before.
        def fine(k):
            return scenario("paper-single-user", lambda d: (
                d.update(name=f"fine-{k}"), d["grid"].update(resolution_m=0.05)))

        results = [None] * 6

        def ask(k):
            results[k] = server.post("/v1/maps", {"scenario": fine(k), "kind": "gain"})

        threads = [threading.Thread(target=ask, args=(k,)) for k in range(len(results))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        statuses = [status for status, _, _ in results]
        expect(all(s == 200 for s in statuses), f"statuses {statuses}: {results}")
        # Jobs: each done job's map answers at once, and nothing is built twice.
        server.stop()
        server = Server("--cache-mb", "64", "--sync-cells", "100")
        jobs = 0
        for k in range(5):
            status, job, _ = server.post("/v1/maps", {"scenario": fine(10 + k), "kind": "gain"})
            expect(status == 202, f"job {k}: {status} {job}")
            done = server.wait_job(job["job_id"])
            expect(done["state"] == "done", f"job {k}: {done}")
            status, _, _ = server.get(f"/v1/maps/{done['map_id']}/coverage?threshold=-60")
            expect(status == 200, f"job {k} says done but its map answers {status}")
            jobs += 1
        builds = server.metric("irs_map_builds_total")
        expect(builds == jobs, f"{builds} builds for {jobs} maps")
        figure("lost-work", f"6 concurrent 1.5 MB maps in a 2 MB cache: statuses {statuses}; "
               f"{jobs} jobs done → map 200 at once, {builds:.0f} builds")
    finally:
        server.stop()


def percentile(samples, p):
    """The p-th percentile (nearest rank) of `samples`."""
    ranked = sorted(samples)
    return ranked[min(len(ranked) - 1, max(0, -(-p * len(ranked) // 100) - 1))]


def starvation():
    """Worst-case sweeps and Monte Carlo checks do not hold the async threads."""
    server = Server()
    try:
        big = scenario("paper-single-user", lambda d: (
            d.update(name="big"), d["grid"].update(resolution_m=0.02)))
        status, job, _ = server.post("/v1/maps", {"scenario": big, "kind": "gain"})
        expect(status == 202, f"1001² map: {status} {job}")
        done = server.wait_job(job["job_id"])
        big_map = done["map_id"]
        paper = server.scenario_id("paper-single-user")
        status, small, _ = server.post("/v1/maps", {"scenario_id": paper, "kind": "gain"})
        expect(status == 200, f"paper map: {status}")
        cheap_path = {"map_id": small["map_id"], "start": [-8, -8], "goal": [8, 8], "threshold": -60}
        # 100 thresholds across the feasible band: each is a full search of the 1001² grid
        # (1000 such take minutes on one query worker, past the request timeout).
        thresholds = [-75 + 0.15 * k for k in range(100)]
        sweep = {"map_id": big_map, "start": [-9.5, 0], "goal": [9.5, 0], "thresholds": thresholds}
        check = {"map_id": big_map, "start": [-9.5, 0], "goal": [9.5, 0], "threshold": "max",
                 "monte_carlo_draws": 300}
        answers = []

        def heavy(body, path):
            answers.append(server.post(path, body, timeout=300)[0])

        threads = [threading.Thread(target=heavy, args=(sweep, "/v1/sweeps")) for _ in range(2)]
        threads += [threading.Thread(target=heavy, args=(check, "/v1/paths")) for _ in range(2)]
        for t in threads:
            t.start()
        time.sleep(0.3)
        health, paths = [], []
        while any(t.is_alive() for t in threads) and len(health) < 1000:
            status, ms = server.timed_get("/healthz")
            expect(status == 200, f"healthz {status}")
            health.append(ms)
            started = time.perf_counter()
            status, _, _ = server.post("/v1/paths", cheap_path, timeout=10)
            expect(status == 200, f"cached path {status}")
            paths.append((time.perf_counter() - started) * 1000)
            time.sleep(0.05)
        for t in threads:
            t.join()
        expect(all(a == 200 for a in answers), f"heavy answers {answers}")
        # A runtime thread held by heavy work would hold these for a whole sweep or check
        # (seconds). The p99 bounds are what a free runtime gives (here ≈ 5 ms); the max bounds
        # leave room for one hiccup of a shared CI machine (one sample of 52 ms in ≈ 550 was
        # seen there), far below a held thread.
        health_p99, paths_p99 = percentile(health, 99), percentile(paths, 99)
        expect(health_p99 < 25, f"healthz p99 {health_p99:.1f} ms")
        expect(paths_p99 < 50, f"cached path p99 {paths_p99:.1f} ms")
        expect(max(health) < 250, f"healthz max {max(health):.1f} ms")
        expect(max(paths) < 250, f"cached path max {max(paths):.1f} ms")
        # A client that leaves cancels its query: the worker is free for the next one at once.
        sock = socket.create_connection(("127.0.0.1", server.port))
        body = json.dumps(sweep).encode()
        sock.sendall(b"POST /v1/sweeps HTTP/1.1\r\nHost: x\r\ncontent-type: application/json\r\n"
                     + f"content-length: {len(body)}\r\n\r\n".encode() + body)
        time.sleep(0.5)
        sock.close()
        started = time.perf_counter()
        one = dict(sweep, thresholds=[-70])
        status, _, _ = server.post("/v1/sweeps", one, timeout=60)
        after_leave = time.perf_counter() - started
        expect(status == 200, f"sweep after a client left: {status}")
        expect(after_leave < 3, f"the abandoned sweep held the worker for {after_leave:.1f} s")
        figure("starvation", f"2 sweeps × 100 thresholds + 2 checks × 300 draws on 1001² "
               f"(answers {sorted(answers)}): healthz p99 {health_p99:.1f} ms, max "
               f"{max(health):.1f} ms over {len(health)}; cached path p99 {paths_p99:.1f} ms, max "
               f"{max(paths):.1f} ms; after a client left mid-sweep the next "
               f"sweep answered in {after_leave:.2f} s")
    finally:
        server.stop()


def slow_loris():
    """200 slow clients are cut off by the timeouts while another client is served."""
    server = Server("--header-timeout-s", "2", "--body-timeout-s", "2", "--idle-timeout-s", "2")
    try:
        sockets = []
        for _ in range(200):
            s = socket.create_connection(("127.0.0.1", server.port))
            s.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-Slow: ")
            sockets.append(s)
        started = time.time()
        served = []
        closed = set()
        while time.time() - started < 6 and len(closed) < len(sockets):
            status, ms = server.timed_get("/healthz")
            served.append((status, ms))
            for k, s in enumerate(sockets):
                if k in closed:
                    continue
                try:
                    s.sendall(b"a")
                    s.setblocking(False)
                    if s.recv(1) == b"":
                        closed.add(k)
                except BlockingIOError:
                    pass
                except OSError:
                    closed.add(k)
                finally:
                    s.setblocking(True)
            time.sleep(0.25)
        elapsed = time.time() - started
        for s in sockets:
            s.close()
        expect(len(closed) == len(sockets), f"{len(sockets) - len(closed)} slow clients still open")
        expect(all(st == 200 and ms < 100 for st, ms in served), f"other client: {served[:5]}")
        # A body that stalls is answered 408; an idle kept-alive connection is closed.
        s = socket.create_connection(("127.0.0.1", server.port))
        s.sendall(b"POST /v1/scenarios HTTP/1.1\r\nHost: x\r\ncontent-type: application/json\r\n"
                  b"content-length: 100\r\n\r\n{\"name\"")
        s.settimeout(10)
        t0 = time.time()
        reply = s.recv(200)
        body_s = time.time() - t0
        expect(b" 408 " in reply.split(b"\r\n")[0], f"stalled body: {reply[:60]!r}")
        s.close()
        s = socket.create_connection(("127.0.0.1", server.port))
        s.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        s.settimeout(10)
        s.recv(500)
        t0 = time.time()
        rest = s.recv(10)
        idle_s = time.time() - t0
        expect(rest == b"" and idle_s < 4, f"idle connection: {rest!r} after {idle_s:.1f} s")
        s.close()
        worst = max(ms for _, ms in served)
        figure("slow-loris", f"200 slow-header clients closed within {elapsed:.1f} s "
               f"(header timeout 2 s); other client served {len(served)}× (max {worst:.1f} ms); "
               f"stalled body → 408 after {body_s:.1f} s; idle keep-alive closed after {idle_s:.1f} s")
    finally:
        server.stop()


def slow_readers():
    """150 clients ask for a 15.8 MB map body and never read: the answers in flight stay within
    their budget, the rest get 503, the stalled connections are closed by the write timeout,
    and a client that reads is served throughout. Then 20 HTTP/2 connections that only PING
    fill --max-connections and are closed by the idle timeout, so a new client gets in."""
    budget_mb, write_s = 64, 3
    server = Server("--answers-in-flight-mb", str(budget_mb), "--write-timeout-s", str(write_s),
                    "--sync-cells", "2000000", "--query-queue", "200")
    try:
        fine = scenario("paper-single-user", lambda d: (
            d.update(name="two-cm"), d["grid"].update(resolution_m=0.02)))
        status, built, _ = server.post("/v1/maps", {"scenario": fine, "kind": "gain"})
        expect(status == 200, f"the 1001² map: {status} {built}")
        path = f"/v1/maps/{built['map_id']}"
        status, _, _ = server.get(path)
        expect(status == 200, f"the body: {status}")
        baseline = server.rss_mb()
        sockets = []
        for _ in range(150):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            s.connect(("127.0.0.1", server.port))
            s.sendall(f"GET {path} HTTP/1.1\r\nHost: x\r\n\r\n".encode())
            sockets.append(s)
        started = time.time()
        peak, health = 0.0, []
        while time.time() - started < write_s - 0.5:
            peak = max(peak, server.rss_mb())
            health.append(server.timed_get("/healthz"))
            time.sleep(0.1)
        # Past the write timeout every unread answer's connection is closed: reading now gets
        # what the socket buffers held (a 503 problem, or part of the body), then the end.
        time.sleep(write_s / 2 + 1)
        refused, cut, whole = 0, 0, 0
        for s in sockets:
            s.settimeout(10)
            data = b""
            try:
                while chunk := s.recv(1 << 16):
                    data += chunk
            except OSError:
                pass
            s.close()
            head = data.split(b"\r\n", 1)[0]
            if b" 503 " in head:
                refused += 1
            elif len(data) < 15_000_000:
                cut += 1
            else:
                whole += 1
        # Answers admitted after the first were cut off reach clients that now read: whole.
        expect(cut >= 1 and refused >= 1, f"cut {cut}, refused {refused}, whole {whole}")
        # Budget, plus the answers being built at the moment (one per query worker) and slack.
        bound = budget_mb + 2 * 16 + 40
        expect(peak - baseline <= bound,
               f"RSS grew {peak - baseline:.0f} MB with 150 unread answers (bound {bound} MB)")
        expect(all(st == 200 and ms < 200 for st, ms in health), f"health: {health[:5]}")
        status, _, _ = server.get(path)
        expect(status == 200, f"a reading client after the flood: {status}")
        worst = max(ms for _, ms in health)
        figure("slow-readers", f"150 unread 15.8 MB answers: RSS +{peak - baseline:.0f} MB "
               f"(budget {budget_mb} MB; unbounded they would hold 2.4 GB); {cut} cut off after "
               f"the {write_s} s write timeout, {refused} refused 503, {whole} read later in full; "
               f"/healthz max {worst:.1f} ms")
    finally:
        server.stop()
    server = Server("--max-connections", "20", "--idle-timeout-s", "2")
    try:
        preface = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
        ping = bytes([0, 0, 8, 6, 0, 0, 0, 0, 0]) + b"12345678"
        pinging = []
        for _ in range(20):
            s = socket.create_connection(("127.0.0.1", server.port))
            s.sendall(preface)
            s.setblocking(False)
            pinging.append(s)
        started, open_ = time.time(), set(range(20))
        while open_ and time.time() - started < 8:
            for k in list(open_):
                try:
                    pinging[k].sendall(ping)
                    while pinging[k].recv(4096):
                        pass
                    open_.discard(k)
                except BlockingIOError:
                    pass
                except OSError:
                    open_.discard(k)
            time.sleep(0.5)
        closed_s = time.time() - started
        for s in pinging:
            s.close()
        expect(not open_, f"{len(open_)} PING-only connections still open after 8 s")
        status, ms = server.timed_get("/healthz")
        expect(status == 200, f"a new client after the PING flood: {status}")
        figure("slow-readers", f"20 PING-only HTTP/2 connections (--max-connections 20) closed "
               f"after {closed_s:.1f} s (idle timeout 2 s); a new client then served in {ms:.1f} ms")
    finally:
        server.stop()


def ownership():
    """With tokens, writes need one and everything belongs to the tenants who asked for it:
    maps (claims), shared builds, jobs and scenarios; and one tenant's flood of inline
    scenarios cannot lock the registry for the others."""
    alice, bob = "alice-reliability-0001", "bob-reliability-000002"
    server = Server("--api-tokens", f"{alice},{bob}", "--max-scenarios", "103", "--workers", "1")
    try:
        multi = scenario("paper-multi-user", lambda d: (
            d.update(name="owned"), d["grid"].update(resolution_m=0.2)))
        status, _, _ = server.post("/v1/maps", {"scenario": multi, "kind": "rate"})
        expect(status == 401, f"anonymous POST: {status}")
        status, job, _ = server.post("/v1/maps", {"scenario": multi, "kind": "rate"}, token=alice)
        expect(status == 202, f"alice's job: {status} {job}")
        path = f"/v1/jobs/{job['job_id']}"
        status, _, _ = server.request("DELETE", path, token=bob)
        expect(status == 404, f"bob cancels alice's job: {status}")
        status, _, _ = server.get(path)
        expect(status == 404, f"an anonymous read of alice's job: {status}")
        _, bobs, _ = server.get("/v1/jobs", token=bob)
        _, alices, _ = server.get("/v1/jobs", token=alice)
        expect(len(bobs["jobs"]) == 0 and len(alices["jobs"]) == 1, f"{bobs} {alices}")
        # Bob asks for the same map: one build, both its owners; alice's cancel is hers only.
        status, shared, _ = server.post("/v1/maps", {"scenario": multi, "kind": "rate"}, token=bob)
        expect(status == 202 and shared["job_id"] == job["job_id"], f"shared build: {shared}")
        status, _, _ = server.request("DELETE", path, token=alice)
        expect(status == 202, f"alice withdraws: {status}")
        time.sleep(0.3)
        status, still, _ = server.get(path, token=bob)
        expect(status == 200 and still["state"] in ("queued", "running", "done"),
               f"bob's build goes on: {status} {still}")
        if still["state"] != "done":
            status, _, _ = server.request("DELETE", path, token=bob)
            expect(status == 202, f"bob lets go: {status}")
            final = server.wait_job(job["job_id"], token=bob)
            expect(final["state"] in ("cancelled", "done"), f"the build stops with the last: {final}")
        # Maps: a claim per tenant; a DELETE withdraws only the caller's.
        small = scenario("small-test", lambda d: d.update(name="claimed"))
        status, mine, _ = server.post("/v1/maps", {"scenario": small, "kind": "gain"}, token=alice)
        expect(status == 200, f"alice's map: {status} {mine}")
        map_path = f"/v1/maps/{mine['map_id']}"
        for who in (None, bob):
            status, _, _ = server.get(map_path, token=who)
            expect(status == 404, f"a map read without a claim: {status}")
        status, _, _ = server.request("DELETE", map_path, token=bob)
        expect(status == 404, f"bob deletes alice's map: {status}")
        status, _, _ = server.post("/v1/maps", {"scenario": small, "kind": "gain"}, token=bob)
        expect(status == 200, f"bob asks for the same map: {status}")
        status, _, _ = server.request("DELETE", map_path, token=alice)
        expect(status == 204, f"alice withdraws her claim: {status}")
        status, _, _ = server.get(map_path, token=bob)
        expect(status == 200, f"the map is still bob's: {status}")
        # The registry (100 API slots): alice's flood of inline scenarios evicts her own.
        started = time.perf_counter()
        for k in range(300):
            doc = scenario("small-test", lambda d, k=k: d.update(name=f"flood-{k}"))
            status, body, _ = server.post("/v1/maps", {"scenario": doc, "kind": "gain"}, token=alice)
            expect(status == 200, f"flood map {k}: {status} {body}")
        flood_s = time.perf_counter() - started
        started = time.perf_counter()
        status, body, _ = server.post("/v1/scenarios", scenario(
            "small-test", lambda d: d.update(name="bob's own")), token=bob)
        bob_ms = (time.perf_counter() - started) * 1000
        expect(status == 201, f"bob registers after the flood: {status} {body}")
        figure("ownership", "anonymous POST 401; bob's cancel of alice's job 404, his listing "
               "0 jobs, hers 1; a shared build outlives alice's cancel; alice's map 404 to bob "
               "and anonymous until bob asks for it, her DELETE leaves it his; "
               f"300 inline-scenario maps of alice's all 200 in {flood_s:.1f} s, then bob's "
               f"registration 201 in {bob_ms:.1f} ms")
    finally:
        server.stop()


def shutdown():
    """SIGTERM cancels what outlives the grace period and exits within grace + 2 s."""
    server = Server("--shutdown-grace-s", "2")
    try:
        multi = scenario("paper-multi-user", lambda d: (
            d.update(name="long"), d["grid"].update(resolution_m=0.125)))
        status, job, _ = server.post("/v1/maps", {"scenario": multi, "kind": "rate"})
        expect(status == 202, f"long job: {status}")
        time.sleep(0.5)
        started = time.time()
        server.proc.send_signal(signal.SIGTERM)
        code = server.proc.wait(timeout=10)
        took = time.time() - started
        expect(code == 0, f"exit code {code}")
        expect(took < 4.0, f"exit took {took:.1f} s")
        log = server.log_text()
        expect(job["job_id"] in log and "cancelled" in log, "no log line names the cancelled job")
        figure("shutdown", f"SIGTERM with a running rate-map build: exit 0 after {took:.2f} s "
               f"(grace 2 s), the log names the cancelled job")
    finally:
        server.stop()


def files():
    """Files are read only if regular and within their cap: a map image that is /dev/zero,
    FIFOs in --scenarios and the data dir, a bad scenario file, a 1 GiB map file, a data dir
    that cannot be written; and a URI past the limit is a problem+json 414."""
    work = pathlib.Path(tempfile.mkdtemp(prefix="irs-reliability-files-"))
    scenarios, data = work / "scenarios", work / "data"
    scenarios.mkdir()
    (scenarios / "zero.yaml").write_text(
        "image: /dev/zero\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.25\n")
    zero = scenario("small-test", lambda d: d.update(name="zero", floor_plan={"map": "zero.yaml"}))
    (scenarios / "zero.json").write_text(json.dumps(zero))
    (scenarios / "broken.json").write_text('{"room": 1}')
    os.mkfifo(scenarios / "fifo.json")
    good = scenario("small-test", lambda d: d.update(name="preloaded"))
    (scenarios / "good.json").write_text(json.dumps(good))
    # The CLI on the /dev/zero image: exit 2 at once, memory untouched.
    started = time.perf_counter()
    cli = subprocess.run([BINARY, "scenario", "--scenario", str(scenarios / "zero.json")],
                         capture_output=True, text=True, timeout=30)
    cli_s = time.perf_counter() - started
    expect(cli.returncode == 2 and "not a regular file (a character device)" in cli.stderr,
           f"CLI on /dev/zero: exit {cli.returncode}: {cli.stderr[-300:]}")
    # The data dir: FIFOs under record names, a sparse 1 GiB map file, and a file where the
    # jobs directory should be (every write there fails, as on a full disk, even for root).
    for sub in ("maps", "scenarios"):
        (data / sub).mkdir(parents=True)
    os.mkfifo(data / "maps" / f"{'ab' * 16}.rec")
    os.mkfifo(data / "scenarios" / "cd34.rec")
    huge = data / "maps" / f"{'ef' * 16}.rec"
    with open(huge, "wb") as f:
        f.write(b"IRSREC\x00\x01" + bytes(32))
        f.truncate(2**30)
    (data / "jobs").write_text("in the way")
    started = time.perf_counter()
    server = kit.Server(BINARY, "--scenarios", str(scenarios), "--data-dir", str(data),
                        timeout=30, start_timeout=30)
    try:
        start_s = time.perf_counter() - started
        ready = server.get("/readyz")
        wrong = problem_mismatch(ready, 503, code="data_dir_unwritable")
        expect(not wrong, f"readyz with an unwritable data dir: {wrong}")
        status, listing, _ = server.get("/v1/scenarios")
        names = sorted(s["name"] for s in listing["scenarios"])
        expect(status == 200 and "preloaded" in names and "zero" not in names, f"{names}")
        log = server.log_text()
        skipped = [name for name in ("zero.json", "broken.json", "fifo.json")
                   if name in log and "scenario file skipped" in log]
        expect(len(skipped) == 3, f"skipped files logged: {skipped}")
        expect("loaded=1 skipped=3" in log, "no start-up summary of the scenarios directory")
        expect("1073741824" in log, "the 1 GiB map file is not reported")
        started = time.perf_counter()
        status, _, _ = server.get(f"/v1/maps/{'ef' * 16}")
        huge_ms = (time.perf_counter() - started) * 1000
        expect(status == 404, f"the 1 GiB map file: {status}")
        # Writable again: ready within a probe period (5 s).
        (data / "jobs").unlink()
        (data / "jobs").mkdir()
        started = time.perf_counter()
        while server.get("/readyz")[0] != 200:
            expect(time.perf_counter() - started < 15, "not ready 15 s after the repair")
            time.sleep(0.2)
        repaired_s = time.perf_counter() - started
        long = server.get("/v1/maps?cursor=" + "a" * 9000)
        wrong = problem_mismatch(long, 414, code="uri_too_long")
        expect(not wrong, f"9 kB URI: {wrong}")
        figure("files", f"CLI on image /dev/zero: exit 2 in {cli_s:.2f} s; serve with a FIFO, "
               f"a /dev/zero image and a broken file in --scenarios and FIFOs, a 1 GiB map file "
               f"and no writable jobs dir in --data-dir: listening in {start_s:.2f} s, 1 loaded "
               f"3 skipped (logged), /readyz 503 data_dir_unwritable, the 1 GiB map 404 in "
               f"{huge_ms:.1f} ms unread; ready {repaired_s:.1f} s after the repair; "
               f"9 kB URI → 414 problem+json")
    finally:
        server.stop()


CASES = {
    "overflow": overflow,
    "cache": cache,
    "lost-work": lost_work,
    "starvation": starvation,
    "slow-loris": slow_loris,
    "slow-readers": slow_readers,
    "ownership": ownership,
    "shutdown": shutdown,
    "files": files,
}


def main():
    global BINARY
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    BINARY = os.path.abspath(sys.argv[1])
    chosen = sys.argv[2:] or list(CASES)
    checks = kit.Checks()
    for name in chosen:
        started = time.time()
        error = None
        try:
            CASES[name]()
        except AssertionError as e:
            error = e
        checks.check(error is None, f"{name} ({time.time() - started:.1f} s)", error)
    checks.finish()


if __name__ == "__main__":
    main()
