#!/usr/bin/env python3
"""Replicas sharing Redis behind HAProxy, as processes on loopback (no containers): the
cluster scenarios of `deploy/compose.yaml`, quick to reproduce on a laptop.

    tests/cluster/cluster_test.py BINARY

Starts redis-server (AOF on, in a temporary directory), three `irs-planner serve --redis-url`
replicas and HAProxy health-checking their /readyz, then checks:
  * single flight: 100 concurrent identical map requests through HAProxy, one build in the
    sum of the replicas' /metrics; the map then answers on every replica without a build;
  * a job's progress and its cancellation work from a replica that does not run it;
  * killing (SIGKILL) the replica that runs a build: another claims it, copies the rows the
    build's checkpoint holds, the job finishes, and the map is bit-identical to the CLI's
    single-process build; stopping one (SIGTERM) mid-build: it stores the rows solved up to
    the stop, and the other copies them;
  * Redis stopped for 20 s under load: every replica degraded, not down (/readyz 200
    "degraded" naming Redis, so HAProxy keeps routing), 0 failed path queries through HAProxy
    on a map the replicas hold, a request that needs Redis gets 503 with Retry-After, no
    replica dies; Redis restarted (its AOF): every replica ready again by itself, the maps
    still there;
  * path-query throughput through HAProxy against one replica hit directly (wrk, same run);
  * Redis content this build did not write (a record that is no scenario, a map that does not
    decode, keys of the wrong type, a lock without expiry, a stream that is not one) repaired
    where it is met; a map finished while Redis was away shared when it returns, built once.
  * one truth: a scenario deleted through a replica that never loaded it is gone, with its
    map, from every replica and from Redis within a second, and so is a map deleted through a
    third replica;
  * graceful stop: a replica with --shutdown-delay-s stopped (SIGTERM) under load behind
    HAProxy: 0 failed requests;
  * tenants: two more replicas with tokens on the same Redis; a map's claims and a shared
    build's owners made on one replica are seen on the other (404 to a tenant without a
    claim, a DELETE withdraws only the caller's claim, a cancel only the caller's interest);
  * bounded Redis: with --redis-maps-mb 1 the least recently used maps are evicted and the
    rest stay within the budget; an evicted map is built again on request.
Everything binds 127.0.0.1 and stops by itself (about a minute on two cores).
"""

import hashlib
import json
import os
import pathlib
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "support"))
import irs_testkit as kit  # noqa: E402
from irs_testkit import free_port, request, scenario, wait_job, wait_until  # noqa: E402

BINARY = None  # set by main
WORK = tempfile.mkdtemp(prefix="irs-cluster-")
CHECKS = kit.Checks(stop_on_failure=True)
check = CHECKS.check


class Redis:
    def __init__(self):
        self.port = free_port()
        self.dir = os.path.join(WORK, "redis")
        os.makedirs(self.dir, exist_ok=True)
        self.start()

    def start(self):
        self.proc = kit.spawn(
            ["redis-server", "--port", str(self.port), "--bind", "127.0.0.1", "--dir", self.dir,
             "--appendonly", "yes", "--save", "", "--protected-mode", "no"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wait_until("redis-server listening", self.answers, 10)

    def answers(self):
        with socket.create_connection(("127.0.0.1", self.port), timeout=1) as s:
            s.sendall(b"PING\r\n")
            return s.recv(16).startswith(b"+PONG")

    def stop(self):
        self.proc.terminate()
        self.proc.wait(10)

    def command(self, *args, db=0):
        """One Redis command (RESP over a socket; arguments as str or bytes) in database `db`:
        its reply, a bulk string as str when it is UTF-8 (bytes otherwise)."""
        with socket.create_connection(("127.0.0.1", self.port), timeout=5) as s:
            def send(*words):
                parts = [a if isinstance(a, bytes) else str(a).encode() for a in words]
                s.sendall(b"*%d\r\n" % len(parts) + b"".join(b"$%d\r\n%s\r\n" % (len(p), p) for p in parts))
            reader = s.makefile("rb")
            if db:
                send("SELECT", db)
                reader.readline()
            send(*args)
            line = reader.readline().rstrip(b"\r\n")
            kind, rest = line[:1], line[1:]
            if kind == b"+":
                return rest.decode()
            if kind == b"-":
                raise RuntimeError(f"Redis {args[0]}: {rest.decode()}")
            if kind == b":":
                return int(rest)
            if kind == b"$":
                if int(rest) < 0:
                    return None
                data = reader.read(int(rest) + 2)[:-2]
                try:
                    return data.decode()
                except UnicodeDecodeError:
                    return data
            raise RuntimeError(f"Redis {args[0]}: unexpected reply {line!r}")


class Replica(kit.Server):
    def __init__(self, redis_port, name, *flags, db=0):
        self.name = name
        empty = os.path.join(WORK, "no-scenarios")
        os.makedirs(empty, exist_ok=True)
        super().__init__(BINARY, "--scenarios", empty, "--redis-url", f"redis://127.0.0.1:{redis_port}/{db}",
                         "--workers", "1", "--max-rate-cells", "50000", *flags, log_path=os.path.join(WORK, f"{name}.log"),
                         env={**os.environ, "RUST_LOG": "info"})

    def builds(self):
        return builds(self.base)

    def ready(self):
        return kit.ready(self.base)


def builds(base):
    """The map builds a replica ran (irs_map_builds_total over its labels)."""
    return kit.metric(base, "irs_map_builds_total")


class HAProxy:
    def __init__(self, replicas):
        self.port = free_port()
        config = os.path.join(WORK, "haproxy.cfg")
        servers = "\n".join(
            f"    server {r.name} 127.0.0.1:{r.port} check inter 500ms fall 2 rise 2" for r in replicas)
        with open(config, "w") as f:
            f.write(f"""global
    maxconn 4096
    # One thread: on a small machine HAProxy competes with the replicas for the cores.
    nbthread 1
defaults
    mode http
    timeout connect 2s
    timeout client 60s
    timeout server 60s
    option http-keep-alive
    http-reuse always
    retries 2
    option redispatch
frontend api
    bind 127.0.0.1:{self.port}
    default_backend replicas
backend replicas
    balance roundrobin
    option httpchk GET /readyz
    http-check expect status 200
{servers}
""")
        self.proc = kit.spawn(["haproxy", "-f", config, "-db"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.base = f"http://127.0.0.1:{self.port}"


def wrk(url, body, seconds=5, connections=16):
    """Path queries like `body` for `seconds`: req/s. Each query's threshold is body's minus
    k·10⁻⁹ (a new k per query, the same path), so no query is answered from the replicas'
    answer cache: the figures measure searches, not lookups."""
    script = os.path.join(WORK, "path.lua")
    prefix, suffix = json.dumps({**body, "threshold": "@"}).split('"@"')
    with open(script, "w") as f:
        f.write('wrk.method = "POST"\nwrk.headers["content-type"] = "application/json"\n'
                f"local prefix, suffix, base = {json.dumps(prefix)}, {json.dumps(suffix)}, {float(body['threshold'])!r}\n"
                "local count, threads = 0, 0\n"
                'setup = function(thread) threads = threads + 1; thread:set("offset", threads * 1e7) end\n'
                "request = function()\n"
                "  count = count + 1\n"
                '  local threshold = string.format("%.9f", base - (offset + count) * 1e-9)\n'
                "  return wrk.format(nil, nil, nil, prefix .. threshold .. suffix)\n"
                "end\n")
    out = subprocess.run(["wrk", "-t2", f"-c{connections}", f"-d{seconds}s", "-s", script, url + "/v1/paths"],
                         capture_output=True, text=True, check=True).stdout
    line = next(l for l in out.splitlines() if l.startswith("Requests/sec"))
    non2xx = [l for l in out.splitlines() if "Non-2xx" in l]
    assert not non2xx, out
    return float(line.split()[1])


class Load:
    """Two clients sending path queries like `body` back to back until stopped, each with a
    new threshold (no answer-cache hit), recording every answer that is not a 200."""

    def __init__(self, base, body):
        self.base, self.body = base, body
        self.done, self.failures, self.running = 0, [], True
        self.lock = threading.Lock()
        self.threads = [threading.Thread(target=self.run, args=(k,)) for k in range(2)]
        for t in self.threads:
            t.start()

    def run(self, k):
        n = 0
        while self.running:
            n += 1
            body = {**self.body, "threshold": self.body["threshold"] - (2 * n + k) * 1e-9}
            try:
                status, answer, _ = request(self.base, "POST", "/v1/paths", body, timeout=10)
            except Exception as e:  # noqa: BLE001 - a transport failure is a failure too
                status, answer = None, repr(e)
            with self.lock:
                self.done += 1
                if status != 200:
                    self.failures.append((status, str(answer)[:200]))

    def stop(self):
        self.running = False
        for t in self.threads:
            t.join()
        return self.done, self.failures


def throughputs(direct_base, proxy_base, bodies, behind):
    """wrk against one replica directly, then through HAProxy, per named path query: the ratios."""
    ratios = {}
    for name, body in bodies.items():
        direct = wrk(direct_base, body)
        through = wrk(proxy_base, body)
        ratios[name] = through / direct
        print(f"path queries on the {name}: {direct:.0f} req/s on one replica directly, "
              f"{through:.0f} req/s through HAProxy to {behind} ({through / direct:.2f}×), "
              "16 connections, 5 s each", flush=True)
    return ratios


def main():
    global BINARY
    BINARY = os.path.abspath(sys.argv[1])
    redis = Redis()
    replicas = [Replica(redis.port, f"replica{i}") for i in range(3)]
    proxy = HAProxy(replicas)
    wait_until("every replica ready", lambda: all(r.ready() for r in replicas), 15)
    wait_until("HAProxy forwarding", lambda: kit.ready(proxy.base), 15)

    # A floor fine enough that its gain map is a job (1001² cells, above --sync-cells) and
    # takes long enough for 100 requests to overlap it.
    fine = scenario("paper-single-user", lambda d: (d.__setitem__("name", "fine"), d["grid"].__setitem__("resolution_m", 0.02)))
    status, created, _ = request(proxy.base, "POST", "/v1/scenarios", fine)
    check(status == 201, f"a scenario registered through HAProxy ({status})")
    fine_id = created["id"]
    answers = []

    def ask():
        answers.append(request(proxy.base, "POST", "/v1/maps", {"scenario_id": fine_id, "kind": "gain"}))

    threads = [threading.Thread(target=ask) for _ in range(100)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    statuses = sorted({a[0] for a in answers})
    check(statuses in ([202], [200, 202], [200]), f"100 concurrent identical requests answered {statuses}")
    jobs = {a[1]["job_id"] for a in answers if a[0] == 202}
    check(len(jobs) == 1, f"one job for all of them ({len(jobs)})")
    job = wait_job(proxy.base, jobs.pop())
    check(job["state"] == "done", f"the job finished: {job['state']}")
    total = sum(r.builds() for r in replicas)
    check(total == 1, f"exactly one build in the sum of the replicas' metrics ({total})")
    map_id = job["map_id"]
    for r in replicas:
        status, _, _ = request(r.base, "GET", f"/v1/maps/{map_id}/coverage?threshold=-60")
        check(status == 200, f"{r.name} serves the map")
    check(sum(r.builds() for r in replicas) == 1, "none of them built it again")
    path = {"map_id": map_id, "start": [-10, 0], "goal": [10, 0], "threshold": -62}
    bodies = {json.dumps(request(r.base, "POST", "/v1/paths", path)[1]["waypoints"]) for r in replicas}
    check(len(bodies) == 1, "every replica answers the same path")

    # A rate map long enough to watch, then cancelled from a replica that is not building it:
    # 201 x 201 cells (hence --max-rate-cells), about 6 s on two cores (at 0.25 m the build had
    # become faster than the cancel: 1.0 s, and the job was done before the DELETE arrived; at
    # 0.125 m, 4.2 s, barely longer than the checkpoint a kill below needs, every 2 s).
    slow = scenario("paper-multi-user", lambda d: (d.__setitem__("name", "slow"), d["grid"].__setitem__("resolution_m", 0.1)))
    status, created, _ = request(proxy.base, "POST", "/v1/scenarios", slow)
    slow_id = created["id"]
    before = [r.builds() for r in replicas]
    status, started, _ = request(replicas[0].base, "POST", "/v1/maps", {"scenario_id": slow_id, "kind": "rate", "access": "oma"})
    check(status == 202, f"a rate-map job ({status})")
    job_id = started["job_id"]

    def builder_known():
        now = [r.builds() for r in replicas]
        return any(n > b for n, b in zip(now, before))

    wait_until("a replica started the build", builder_known, 15)
    builder = next(r for r, b in zip(replicas, before) if r.builds() > b)
    other = next(r for r in replicas if r is not builder)
    wait_until("progress visible from another replica",
               lambda: request(other.base, "GET", f"/v1/jobs/{job_id}")[1]["cells_done"] > 0, 15)
    check(True, f"{builder.name} builds, {other.name} shows its progress")
    status, _, _ = request(other.base, "DELETE", f"/v1/jobs/{job_id}")
    check(status == 202, f"cancelled through {other.name} ({status})")
    job = wait_job(other.base, job_id, 20)
    check(job["state"] == "cancelled", f"the build stopped: {job['state']}")

    # The same map again; its builder is killed mid-build, after its first checkpoint, and
    # another replica finishes it from the rows checkpointed.
    before = [r.builds() for r in replicas]
    status, started, _ = request(replicas[0].base, "POST", "/v1/maps", {"scenario_id": slow_id, "kind": "rate", "access": "noma"})
    job_id = started["job_id"]
    wait_until("a replica started the build", builder_known, 15)
    builder = next(r for r, b in zip(replicas, before) if r.builds() > b)
    survivors = [r for r in replicas if r is not builder]
    wait_until("the builder checkpointed rows", lambda: builder.metric("irs_map_rows_checkpointed_total") > 0, 15)
    checkpointed = builder.metric("irs_map_rows_checkpointed_total")
    builder.proc.send_signal(signal.SIGKILL)
    builder.proc.wait()
    killed_at = time.time()
    job = wait_job(survivors[0].base, job_id, 120)
    check(job["state"] == "done", f"after SIGKILL of {builder.name} the job finished on another replica "
                                  f"in {time.time() - killed_at:.1f} s")
    check(sum(r.builds() for r in survivors) >= 1, "a survivor built it")
    resumed = sum(r.metric("irs_map_rows_resumed_total") for r in survivors)
    check(resumed >= checkpointed > 0, f"the survivor copied {resumed:.0f} of the 201 rows from the checkpoint "
                                       f"({checkpointed:.0f} stored before the kill) instead of solving them")
    check(redis.command("EXISTS", f"irs:checkpoint:{job['map_id']}") == 0, "the checkpoint went with the build")
    status, shared, _ = request(survivors[1].base, "GET", f"/v1/maps/{job['map_id']}")
    check(status == 200, "the map answers")
    slow_file = os.path.join(WORK, "slow.json")
    with open(slow_file, "w") as f:
        json.dump(slow, f)
    cli = subprocess.run([BINARY, "map", "--scenario", slow_file, "--kind", "rate", "--access", "noma", "--quiet"],
                         capture_output=True, text=True, check=True)
    alone = json.loads(cli.stdout)
    check(shared["values"] == alone["values"], "bit-identical to a single-process build (every cell)")

    # Redis goes away, under load. The paper map is held by both survivors first (a path
    # query on each), as a map in use is.
    cached = survivors[0]
    wait_until("HAProxy routes to the survivors only", lambda: kit.ready(proxy.base), 15)
    paper = kit.scenario_id(proxy.base, "paper-single-user")
    status, built, _ = request(proxy.base, "POST", "/v1/maps", {"scenario_id": paper, "kind": "gain"})
    small_path = {"map_id": built["map_id"], "start": [-10, 0], "goal": [10, 0], "threshold": -62}
    for r in survivors:
        request(r.base, "POST", "/v1/paths", small_path)
        request(r.base, "POST", "/v1/paths", path)
    load = Load(proxy.base, small_path)
    time.sleep(1)
    redis.stop()
    stopped_at = time.time()

    def degraded(r):
        status, ready, _ = request(r.base, "GET", "/readyz", timeout=5)
        names = [d.get("component") for d in ready.get("degraded", [])] if status == 200 else []
        return status == 200 and ready.get("status") == "degraded" and names == ["shared_store"]
    wait_until("every replica degraded, still ready", lambda: all(degraded(r) for r in survivors), 10)
    status, ready, _ = request(cached.base, "GET", "/readyz")
    check("Redis" in ready["degraded"][0].get("reason", ""), f"readyz names the reason: {ready['degraded']}")
    status, _, _ = request(cached.base, "POST", "/v1/paths", path)
    check(status == 200, "a cached map still answers path queries")
    status, problem, headers = request(cached.base, "POST", "/v1/scenarios", scenario("small-test", lambda d: d.__setitem__("name", "while-down")))
    check(status == 503 and "retry-after" in headers, f"a request that needs Redis: {status}, Retry-After: {headers.get('retry-after')}")
    status, _, headers = request(cached.base, "GET", "/v1/maps/0123456789abcdef0123456789abcdef")
    check(status == 503, f"an unknown map cannot be looked up: {status}")
    check(all(r.proc.poll() is None for r in survivors), "no replica died")
    time.sleep(max(0.0, 20 - (time.time() - stopped_at)))
    done, failures = load.stop()
    print(f"Redis stopped for {time.time() - stopped_at:.0f} s: {done} path queries through HAProxy, "
          f"{len(failures)} failed", flush=True)
    check(done > 0 and not failures, f"0 failed path queries on a held map while Redis was down "
                                     f"({len(failures)} of {done}: {failures[:3]})")
    redis.start()
    wait_until("every replica ready again by itself", lambda: all(r.ready() for r in survivors), 15)
    status, _, _ = request(survivors[1].base, "GET", f"/v1/maps/{job['map_id']}/coverage?threshold=1")
    check(status == 200, "the maps survived Redis's restart (AOF)")

    # Throughput: HAProxy in front of the two survivors against one of them directly, on
    # the paper's map (41², about a millisecond a query: HAProxy's own cost shows) and on the
    # 1001² one. There the grid path is a 0.15 ms search and a 0.6 MB answer, whose relay
    # through HAProxy costs about what the query does (0.67–0.83× on a 2.4 GHz host): reported.
    # The any-angle path (an A* from the goal and Lazy Theta*, ~5 ms) is real work per query,
    # where the replicas share it and the proxy must not be the bottleneck: asserted, as the
    # compose test does.
    any_angle = {**path, "path_shape": "any_angle"}
    ratios = throughputs(cached.base, proxy.base, {"41² paper map": small_path, "1001² map": path,
                                                   "1001² map, any-angle": any_angle}, "two")
    # On the 41² map a query costs about what HAProxy's own hop costs, and on a two-core
    # machine wrk, HAProxy and the replicas share the same cores, so the ratio there measures
    # the machine (reported, not asserted).
    check(ratios["1001² map, any-angle"] >= 0.8,
          "HAProxy keeps at least 80 % of one replica's throughput (1001² map, any-angle paths)")
    tenants(redis)
    repairs(redis, survivors)
    one_truth(redis, survivors)
    graceful_stop(redis)
    stopped_mid_build(redis, slow)
    bounded(redis)


def gone_everywhere(replicas, path, seconds=1.0):
    """Waits until every replica answers 404 for `path`: the seconds it took, or None."""
    started = time.time()
    while time.time() - started < seconds:
        if all(request(r.base, "GET", path)[0] == 404 for r in replicas):
            return time.time() - started
        time.sleep(0.02)
    return None


def one_truth(redis, survivors):
    """A delete on any replica is seen by every replica within a second: a scenario (with
    the maps built from it) deleted through a replica that never loaded it, and a map deleted
    through a third; neither stays in Redis."""
    owner, reader = survivors
    third = Replica(redis.port, "third")  # has loaded nothing: it must find both in Redis
    # Redis was just restarted (repairs): every replica connected again, not degraded.
    wait_until("the replicas ready", lambda: all(r.ready() for r in (owner, reader, third)), 15)
    everyone = [owner, reader, third]
    doc = scenario("small-test", lambda d: d.__setitem__("name", "one-truth"))
    status, created, _ = request(owner.base, "POST", "/v1/scenarios", doc)
    sid = created["id"]
    status, built, _ = request(owner.base, "POST", "/v1/maps", {"scenario_id": sid, "kind": "gain"})
    map_id = built["map_id"]
    query = {"map_id": map_id, "start": [0.5, 0.5], "goal": [5.5, 0.5], "threshold": -200}
    check(request(reader.base, "POST", "/v1/paths", query)[0] == 200
          and request(reader.base, "GET", f"/v1/scenarios/{sid}")[0] == 200,
          "another replica serves the scenario and its map (both held there now)")
    status, _, _ = request(third.base, "DELETE", f"/v1/scenarios/{sid}")
    check(status == 204, f"DELETE through a replica that never loaded the scenario: {status} (was 404)")
    took = gone_everywhere(everyone, f"/v1/scenarios/{sid}")
    check(took is not None, f"the scenario is gone from every replica within a second ({took and round(took, 3)} s)")
    took_map = gone_everywhere(everyone, f"/v1/maps/{map_id}")
    check(took_map is not None and redis.command("EXISTS", f"irs:map:{map_id}") == 0
          and redis.command("EXISTS", f"irs:scenario:{sid}") == 0,
          f"its map too, everywhere and in Redis ({took_map and round(took_map, 3)} s)")

    status, created, _ = request(owner.base, "POST", "/v1/scenarios", doc)
    status, built, _ = request(owner.base, "POST", "/v1/maps", {"scenario_id": created["id"], "kind": "gain"})
    check(request(reader.base, "POST", "/v1/paths", {**query, "map_id": built["map_id"]})[0] == 200,
          "registered and built again, held by another replica")
    status, _, _ = request(third.base, "DELETE", f"/v1/maps/{built['map_id']}")
    took = gone_everywhere(everyone, f"/v1/maps/{built['map_id']}")
    check(status == 204 and took is not None,
          f"a map deleted through a third replica: {status}, gone from every replica in {took and round(took, 3)} s")
    print(f"deletes seen by every replica in {max(took, took_map):.3f} s at most", flush=True)
    third.stop()


def graceful_stop(redis):
    """A replica stopped (SIGTERM) under load behind HAProxy loses no request: with
    --shutdown-delay-s it answers /readyz 503 and keeps serving until HAProxy's checks (every
    0.5 s, out after two failures) take it out, then drains."""
    staying = Replica(redis.port, "staying")
    leaving = Replica(redis.port, "leaving", "--shutdown-delay-s", "2")
    proxy = HAProxy([staying, leaving])
    wait_until("both replicas ready", lambda: staying.ready() and leaving.ready(), 15)
    wait_until("HAProxy forwarding", lambda: kit.ready(proxy.base), 15)
    paper = kit.scenario_id(proxy.base, "paper-single-user")
    status, built, _ = request(proxy.base, "POST", "/v1/maps", {"scenario_id": paper, "kind": "gain"})
    query = {"map_id": built["map_id"], "start": [-10, 0], "goal": [10, 0], "threshold": -62}
    for r in (staying, leaving):
        request(r.base, "POST", "/v1/paths", query)
    time.sleep(1.5)  # both in rotation (rise 2 at 500 ms)
    load = Load(proxy.base, query)
    time.sleep(1)
    served_before = load.done
    leaving.proc.send_signal(signal.SIGTERM)
    stopped = time.time()
    leaving.proc.wait(15)
    exit_s = time.time() - stopped
    time.sleep(1)
    done, failures = load.stop()
    print(f"graceful stop under load: {done} path queries through HAProxy ({served_before} before the "
          f"SIGTERM), {len(failures)} failed; the replica exited {exit_s:.1f} s after SIGTERM", flush=True)
    check(leaving.proc.returncode == 0 and not failures,
          f"a replica stopped under load: exit {leaving.proc.returncode}, {len(failures)} of {done} "
          f"queries failed {failures[:3]}")
    kit.stop_process(proxy.proc)
    staying.stop()


def stopped_mid_build(redis, slow):
    """A replica stopped (SIGTERM, no grace) while it builds a rate map stores the rows it
    solved in the build's checkpoint before it exits; the other replica takes the build over
    under the same job and copies those rows instead of solving them again."""
    # A database of their own: the replicas of the earlier checks, still running, read the
    # build stream of database 0.
    first, second = (Replica(redis.port, name, "--shutdown-grace-s", "0", db=2) for name in ("first", "second"))
    wait_until("both replicas ready", lambda: first.ready() and second.ready(), 15)
    status, created, _ = request(first.base, "POST", "/v1/scenarios", slow)
    status, started, _ = request(first.base, "POST", "/v1/maps", {"scenario_id": created["id"], "kind": "rate", "access": "oma"})
    check(status == 202, f"a rate-map job ({status})")
    job_id = started["job_id"]
    wait_until("a replica started the build", lambda: first.builds() + second.builds() > 0, 15)
    builder, other = (first, second) if first.builds() > 0 else (second, first)
    wait_until("the builder checkpointed rows", lambda: builder.metric("irs_map_rows_checkpointed_total") > 0, 15)
    checkpointed = builder.metric("irs_map_rows_checkpointed_total")
    # Half a checkpoint period more: rows that only the checkpoint stored at the stop holds.
    time.sleep(1)
    builder.proc.send_signal(signal.SIGTERM)
    stopped = time.time()
    builder.proc.wait(40)
    exit_s = time.time() - stopped
    job = wait_job(other.base, job_id, 120)
    resumed = other.metric("irs_map_rows_resumed_total")
    print(f"stopped mid-build: {builder.name} exited {builder.proc.returncode} {exit_s:.1f} s after SIGTERM; "
          f"{other.name} finished the job {time.time() - stopped:.1f} s after it, {resumed:.0f} of 201 rows copied "
          f"from the checkpoint ({checkpointed:.0f} stored before the SIGTERM)", flush=True)
    check(builder.proc.returncode == 0 and job["state"] == "done",
          f"the job finished on {other.name} after {builder.name}'s graceful stop: {job['state']}")
    check(resumed > checkpointed > 0, f"the rows solved up to the stop were copied, not solved again "
                                      f"({resumed:.0f} > {checkpointed:.0f})")
    check(redis.command("EXISTS", f"irs:checkpoint:{job['map_id']}", db=2) == 0, "the checkpoint went with the build")
    status, _, _ = request(other.base, "GET", f"/v1/maps/{job['map_id']}")
    check(status == 200, "the map answers")
    other.stop()


def tenants(redis):
    """Two replicas with tokens: claims and shared builds' owners live in Redis, so what one
    replica recorded for a tenant holds on the other."""
    alice, bob = "alice-cluster-token-01", "bob-cluster-token-0002"
    one, two = (Replica(redis.port, f"tenant{i}", "--api-tokens", f"{alice},{bob}") for i in range(2))
    wait_until("the tenants' replicas ready", lambda: one.ready() and two.ready(), 15)
    small = scenario("small-test", lambda d: d.update(name="cluster-claims"))
    status, mine, _ = request(one.base, "POST", "/v1/maps", {"scenario": small, "kind": "gain"}, token=alice)
    check(status == 200, f"alice's map on {one.name} ({status})")
    map_path = f"/v1/maps/{mine['map_id']}"
    status, _, _ = request(two.base, "GET", map_path, token=alice)
    check(status == 200, f"her claim holds on {two.name} ({status})")
    for who in (bob, None):
        status, _, _ = request(two.base, "GET", map_path, token=who)
        check(status == 404, f"no claim, no map on {two.name} ({status})")
    status, _, _ = request(two.base, "POST", "/v1/maps", {"scenario": small, "kind": "gain"}, token=bob)
    check(status == 200, f"bob asks for the same map on {two.name} ({status})")
    status, _, _ = request(two.base, "DELETE", map_path, token=alice)
    check(status == 204, f"alice withdraws her claim on {two.name} ({status})")
    status, _, _ = request(one.base, "GET", map_path, token=alice)
    check(status == 404, f"withdrawn on {one.name} too ({status})")
    status, _, _ = request(one.base, "GET", map_path, token=bob)
    check(status == 200, f"still bob's on {one.name} ({status})")
    status, _, _ = request(one.base, "DELETE", map_path, token=bob)
    check(status == 204, f"bob's, the last claim ({status})")
    status, _, _ = request(two.base, "GET", map_path, token=bob)
    check(status == 404, f"the map went with the last claim ({status})")

    # N = 240 sub-surfaces: a build of several seconds, so both cancels land while it runs.
    multi = scenario("paper-multi-user", lambda d: (
        d.update(name="cluster-shared"), d["grid"].update(resolution_m=0.2),
        d["irs"].update(nx_sub=40)))
    status, first, _ = request(one.base, "POST", "/v1/maps", {"scenario": multi, "kind": "rate", "access": "noma"}, token=alice)
    check(status == 202, f"alice's rate map is a job on {one.name} ({status})")
    status, second, _ = request(two.base, "POST", "/v1/maps", {"scenario": multi, "kind": "rate", "access": "noma"}, token=bob)
    check(status == 202 and second["job_id"] == first["job_id"], f"bob shares it from {two.name} ({second.get('job_id')})")
    job_path = f"/v1/jobs/{first['job_id']}"
    for base, who in ((two.base, alice), (one.base, bob)):
        status, _, _ = request(base, "GET", job_path, token=who)
        check(status == 200, f"an owner follows it on either replica ({status})")
    status, _, _ = request(one.base, "GET", job_path)
    check(status == 404, f"an anonymous read of the shared job ({status})")
    status, _, _ = request(two.base, "DELETE", job_path, token=alice)
    check(status == 202, f"alice withdraws from {two.name} ({status})")
    time.sleep(1.0)  # two heartbeats: a cancel would have been seen by now
    status, job, _ = request(one.base, "GET", job_path, token=bob)
    check(status == 200 and job["state"] != "cancelled", f"the build goes on for bob ({job.get('state')})")
    status, _, _ = request(one.base, "GET", job_path, token=alice)
    check(status == 404, f"alice's interest is gone ({status})")
    if job["state"] != "done":
        status, _, _ = request(one.base, "DELETE", job_path, token=bob)
        check(status == 202, f"bob, the last owner, cancels ({status})")
        job = wait_job(one.base, first["job_id"], 60, token=bob)
        check(job["state"] == "cancelled", f"the build stopped with the last owner ({job['state']})")
    for replica in (one, two):  # the checks after these count builds over the other replicas
        replica.stop()


def bounded(redis):
    """Two replicas whose maps may take 1 MiB of Redis (--redis-maps-mb 1): storing past it evicts the least recently used maps, the maps stay
    within it, an evicted map is built again on request (and still answered by a replica that
    holds it), and a map bigger than the budget is refused before its build."""
    # A database of their own: the replicas of the other checks (default budget) would build
    # and store maps in theirs too.
    one, two = (Replica(redis.port, f"bounded{i}", "--redis-maps-mb", "1", db=1) for i in range(2))
    wait_until("the bounded replicas ready", lambda: one.ready() and two.ready(), 15)
    budget = 1 << 20
    # 201 x 201 cells, about 0.36 MB each in Redis: two fit in 1 MiB, the third needs room.
    maps = []
    for i in range(5):
        floor = scenario("paper-single-user", lambda d: (d.update(name=f"bounded-{i}"), d["grid"].update(resolution_m=0.1)))
        status, built, _ = request(one.base, "POST", "/v1/maps", {"scenario": floor, "kind": "gain"})
        check(status == 200, f"map {i} built ({status})")
        maps.append(built["map_id"])
    stored = [m for m in maps if redis.command("EXISTS", f"irs:map:{m}", db=1) == 1]
    total = sum(int(redis.command("HGET", "irs:map-sizes", m, db=1) or 0) for m in stored)
    check(redis.command("HLEN", "irs:map-sizes", db=1) == len(stored),
          "the budget counts the stored maps, and only them")
    # Whichever replica had a free worker built each map and stored it.
    evicted = sum(r.metric("irs_redis_maps_evicted_total") for r in (one, two))
    print(f"5 maps of about {total / max(len(stored), 1) / 1e6:.2f} MB stored with a 1 MiB budget: "
          f"{len(stored)} kept ({total} bytes), {evicted:.0f} evicted", flush=True)
    check(maps[0] not in stored and maps[-1] in stored and evicted >= 1,
          f"the least recently used evicted ({len(stored)} of 5 kept, {evicted:.0f} evictions)")
    check(total <= budget, f"the maps within the budget ({total} <= {budget} bytes)")
    check(total in [r.metric("irs_redis_map_bytes") for r in (one, two)],
          "irs_redis_map_bytes says so (on the replica that stored last)")
    status, _, _ = request(one.base, "GET", f"/v1/maps/{maps[0]}")
    check(status == 200, f"the replica holding the evicted map still answers it ({status})")
    # A replica started now holds nothing: it must read Redis.
    fresh = Replica(redis.port, "bounded2", "--redis-maps-mb", "1", db=1)
    wait_until("the fresh bounded replica ready", fresh.ready, 15)
    status, _, _ = request(fresh.base, "GET", f"/v1/maps/{maps[0]}")
    check(status == 404, f"a replica without it: not found, as any map let go of ({status})")
    status, _, _ = request(fresh.base, "GET", f"/v1/maps/{maps[-1]}")
    check(status == 200, f"one still in Redis: read from there ({status})")
    floor = scenario("paper-single-user", lambda d: (d.update(name="bounded-0"), d["grid"].update(resolution_m=0.1)))
    status, again, _ = request(fresh.base, "POST", "/v1/maps", {"scenario": floor, "kind": "gain"})
    check(status == 200 and again["map_id"] == maps[0], f"requested again: built again ({status})")
    path = {"map_id": maps[0], "start": [-10, 0], "goal": [10, 0], "threshold": -70}
    status, _, _ = request(fresh.base, "POST", "/v1/paths", path)
    check(status == 200, f"and its paths answer ({status})")
    fine = scenario("paper-single-user", lambda d: (d.update(name="bounded-fine"), d["grid"].update(resolution_m=0.02)))
    status, problem, _ = request(one.base, "POST", "/v1/maps", {"scenario": fine, "kind": "gain"})
    check(status == 422 and problem.get("field") == "kind" and "--redis-maps-mb" in problem.get("detail", ""),
          f"a map bigger than the budget refused before its build: {status} {problem.get('detail', '')[:120]}")
    for replica in (one, two, fresh):
        replica.stop()


def repairs(redis, survivors):
    """Redis content this build did not write heals itself: wrong records and maps are deleted
    and built or registered again, wrong types repaired, a lock without expiry given one, and a
    map finished while Redis was away is shared once it returns rather than built twice."""
    fresh = Replica(redis.port, "fresh")  # nothing cached or registered: it must read Redis
    wait_until("the fresh replica ready", fresh.ready, 15)
    owner = survivors[0]
    plain = scenario("small-test", lambda d: d.__setitem__("name", "repairs"))
    status, created, _ = request(owner.base, "POST", "/v1/scenarios", plain)
    plain_id = created["id"]
    key = f"irs:scenario:{plain_id}"
    redis.command("SET", key, json.dumps({"document": {"name": "not a scenario"}, "owners": []}))
    status, _, _ = request(fresh.base, "GET", f"/v1/scenarios/{plain_id}")
    check(status == 404 and redis.command("EXISTS", key) == 0,
          f"a scenario record that is no scenario: {status} and deleted (was a 500 on every request)")
    request(owner.base, "POST", "/v1/scenarios", plain)
    status, _, _ = request(fresh.base, "GET", f"/v1/scenarios/{plain_id}")
    check(status == 200, f"registered again by the replica that has it, read back: {status}")

    status, built, _ = request(owner.base, "POST", "/v1/maps", {"scenario_id": plain_id, "kind": "gain"})
    check(status == 200, f"a small map built ({status})")
    map_id = built["map_id"]
    key = f"irs:map:{map_id}"
    magic = redis.command("GETRANGE", key, 0, 7)  # the frame's magic bytes (store::disk)
    magic = magic.encode() if isinstance(magic, str) else magic
    garbage = b"not a map of this build"
    redis.command("SET", key, magic + hashlib.sha256(garbage).digest() + garbage)
    status, _, _ = request(fresh.base, "GET", f"/v1/maps/{map_id}")
    check(status == 404 and redis.command("EXISTS", key) == 0,
          f"a map that frames but does not decode: {status} and deleted (was a 500 on every request)")
    redis.command("RPUSH", key, "x")
    status, _, _ = request(fresh.base, "GET", f"/v1/maps/{map_id}")
    check(status == 404 and redis.command("EXISTS", key) == 0,
          f"a map key of the wrong type: {status} and deleted (was a 503 on every request)")
    redis.command("SET", f"irs:building:{map_id}", "a-job-nobody-runs")
    started = time.time()
    status, _, _ = request(fresh.base, "POST", "/v1/maps", {"scenario_id": plain_id, "kind": "gain"})
    waited = time.time() - started
    check(status == 200 and waited < 15,
          f"a build lock without expiry: the map built after {waited:.1f} s (was 120 s, then 504)")
    check(redis.command("EXISTS", key) == 1, "the map is shared again")

    redis.command("DEL", "irs:builds")
    redis.command("SET", "irs:builds", "not a stream")
    wait_until("every replica ready with the stream repaired",
               lambda: redis.command("TYPE", "irs:builds") == "stream"
               and all(r.ready() for r in [fresh, *survivors]), 10)
    repaired = sum(kit.metric(r.base, "irs_redis_repaired_total") for r in [fresh, *survivors])
    check(repaired >= 5, f"every repair counted (irs_redis_repaired_total {repaired:.0f})")

    # A build that ends while Redis is away: shared when Redis returns, not built again.
    slow = scenario("paper-multi-user", lambda d: (d.__setitem__("name", "slow"), d["grid"].__setitem__("resolution_m", 0.125)))
    slow_id = request(fresh.base, "POST", "/v1/scenarios", slow)[1]["id"]
    replicas = [fresh, *survivors]
    before = sum(r.builds() for r in replicas)
    status, started, _ = request(fresh.base, "POST", "/v1/maps", {"scenario_id": slow_id, "kind": "rate", "access": "oma"})
    job_id = started["job_id"]
    wait_until("the build under way", lambda: request(fresh.base, "GET", f"/v1/jobs/{job_id}")[1]["cells_done"] > 0, 15)
    redis.stop()
    time.sleep(8)  # the build (about 4 s) ends while Redis is down
    redis.start()
    # As another replica sees it (the record in Redis, written once the map is shared there).
    job = wait_job(survivors[0].base, job_id, 60)
    builds_run = sum(r.builds() for r in replicas) - before
    check(job["state"] == "done" and builds_run == 1,
          f"a map finished while Redis was away: {job['state']} after {builds_run:.0f} build(s) "
          f"(was done → running → done, built twice)")
    status, problem, _ = request(survivors[0].base, "GET", f"/v1/maps/{job['map_id']}/coverage?threshold=1")
    check(status == 200, f"and shared: another replica serves it ({status} {str(problem)[:200]})")


if __name__ == "__main__":
    code = 1
    try:
        code = CHECKS.run(main)
    finally:
        if code:
            # What the replicas logged, to see why.
            for name in sorted(os.listdir(WORK)):
                if name.endswith(".log"):
                    with open(os.path.join(WORK, name)) as f:
                        lines = f.readlines()
                    print(f"--- {name} (last 15 lines)\n" + "".join(lines[-15:]), file=sys.stderr)
        kit.stop_all()
        shutil.rmtree(WORK, ignore_errors=True)
    sys.exit(code)
