#!/usr/bin/env python3
"""The container, run from the host: health endpoints, a scenario registered, a path answer
identical to the CLI's, a non-root process, a HEALTHCHECK that reports healthy, persistence in
the image's volume across a restart, and `docker stop` ending the server gracefully (SIGTERM
reaches it as PID 1) within 10 s. Prints the image size and fails above 120 MB.

    tests/container/container_test.py IMAGE CLI_BINARY
"""
import json
import subprocess
import sys
import time
import urllib.request
import uuid

IMAGE, CLI = sys.argv[1], sys.argv[2]
NAME = f"irs-ci-{uuid.uuid4().hex[:8]}"
VOLUME = f"{NAME}-data"
MAX_IMAGE_MB = 120


def docker(*args, check=True):
    out = subprocess.run(["docker", *args], capture_output=True, text=True)
    if check and out.returncode != 0:
        raise SystemExit(f"docker {' '.join(args)}: {out.stderr.strip()}")
    return out.stdout.strip()


def request(base, method, path, body=None):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(base + path, data, method=method,
                                 headers={"content-type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=60) as resp:
            return resp.status, resp.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode()


def wait_ready(base, seconds=30):
    deadline = time.time() + seconds
    while time.time() < deadline:
        try:
            if request(base, "GET", "/readyz")[0] == 200:
                return
        except OSError:
            pass
        time.sleep(0.2)
    raise SystemExit(f"{base}/readyz not 200 within {seconds} s:\n{docker('logs', NAME, check=False)}")


def metric(base, name):
    text = request(base, "GET", "/metrics")[1]
    values = [float(l.rsplit(" ", 1)[1]) for l in text.splitlines() if l.startswith(name)]
    return sum(values)


def check(condition, message):
    if not condition:
        raise SystemExit(f"FAIL: {message}")
    print(f"ok: {message}")


def main():
    size_mb = int(docker("image", "inspect", "--format", "{{.Size}}", IMAGE)) / 1e6
    print(f"image {IMAGE}: {size_mb:.1f} MB")
    check(size_mb <= MAX_IMAGE_MB, f"runtime image {size_mb:.1f} MB <= {MAX_IMAGE_MB} MB")
    health = json.loads(docker("image", "inspect", "--format", "{{json .Config.Healthcheck}}", IMAGE))
    check(health and health.get("Test"), f"the image declares a HEALTHCHECK: {health}")

    docker("run", "-d", "--name", NAME, "-p", "127.0.0.1::8080", "-v", f"{VOLUME}:/var/lib/irs-planner", IMAGE)
    try:
        port = docker("port", NAME, "8080/tcp").splitlines()[0].rsplit(":", 1)[1]
        base = f"http://127.0.0.1:{port}"
        wait_ready(base)
        check(request(base, "GET", "/healthz")[0] == 200, "/healthz answers 200")
        check(request(base, "GET", "/readyz")[0] == 200, "/readyz answers 200")

        uid = docker("exec", NAME, "id", "-u")
        check(uid != "0", f"the server runs as uid {uid}, not root")
        pid1 = docker("exec", NAME, "cat", "/proc/1/cmdline").replace("\0", " ").strip()
        check(pid1.startswith("irs-planner"), f"PID 1 is the server ({pid1!r})")

        with open("scenarios/small-test.json") as f:
            doc = json.load(f)
        doc["name"] = "container-test"
        status, body = request(base, "POST", "/v1/scenarios", doc)
        check(status == 201, f"a scenario is registered ({status})")

        listed = json.loads(request(base, "GET", "/v1/scenarios")[1])["scenarios"]
        paper = next(s["id"] for s in listed if s["name"] == "paper-single-user")
        status, body = request(base, "POST", "/v1/maps", {"scenario_id": paper, "kind": "gain"})
        map_id = json.loads(body)["map_id"]
        path_request = {"map_id": map_id, "start": [-10, 0], "goal": [10, 0], "threshold": "max"}
        status, api_body = request(base, "POST", "/v1/paths", path_request)
        check(status == 200, "a path is planned")
        cli = subprocess.run([CLI, "plan", "--scenario", "scenarios/paper-single-user.json",
                              "--kind", "gain", "--start=-10,0", "--goal", "10,0",
                              "--max-threshold", "--quiet"], capture_output=True, text=True, check=True)
        untimed = lambda body: body.strip().rsplit(',"took_ms":', 1)[0]
        check(untimed(api_body) == untimed(cli.stdout), "the path answer is the CLI's, byte for byte")

        deadline = time.time() + 40
        state = ""
        while time.time() < deadline:
            state = docker("inspect", "--format", "{{.State.Health.Status}}", NAME)
            if state == "healthy":
                break
            time.sleep(1)
        check(state == "healthy", f"docker reports the container {state}")

        started = time.time()
        docker("stop", "--time", "10", NAME)
        took = time.time() - started
        code = docker("inspect", "--format", "{{.State.ExitCode}}", NAME)
        logs = docker("logs", NAME, check=False) + subprocess.run(
            ["docker", "logs", NAME], capture_output=True, text=True).stderr
        check(code == "0", f"docker stop: exit code {code} (137 would mean SIGKILL)")
        check(took < 10, f"docker stop took {took:.2f} s (< 10 s)")
        check("shutdown complete" in logs, "the server logged its graceful shutdown")

        # The volume keeps the map: after a restart it answers without a build.
        docker("start", NAME)
        port = docker("port", NAME, "8080/tcp").splitlines()[0].rsplit(":", 1)[1]
        base = f"http://127.0.0.1:{port}"
        wait_ready(base)
        status, _ = request(base, "GET", f"/v1/maps/{map_id}")
        check(status == 200, "after a restart the map is served from the volume")
        status, again = request(base, "POST", "/v1/paths", path_request)
        check(untimed(again) == untimed(api_body), "and the same path is answered")
        check(metric(base, "irs_map_builds_total") == 0, "without building it again")
    finally:
        docker("rm", "-f", NAME, check=False)
        docker("volume", "rm", "-f", VOLUME, check=False)


if __name__ == "__main__":
    main()
