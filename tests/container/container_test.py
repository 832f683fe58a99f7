#!/usr/bin/env python3
"""The container, run from the host: health endpoints, a scenario registered, a path answer
identical to the CLI's, a non-root process, a HEALTHCHECK that reports healthy, persistence in
the image's volume across a restart, and `docker stop` ending the server gracefully (SIGTERM
reaches it as PID 1) within 10 s; then the same image run as an arbitrary uid (`--user
12345:0`, as OpenShift runs images) keeping a map in its volume across a restart; and the OCI
labels (version as the server reports it, licence, revision). Prints the image size and fails
above 120 MB.

    tests/container/container_test.py IMAGE CLI_BINARY
"""
import json
import pathlib
import subprocess
import sys
import time
import uuid

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "support"))
import irs_testkit as kit  # noqa: E402

IMAGE, CLI = sys.argv[1], sys.argv[2]
NAME = f"irs-ci-{uuid.uuid4().hex[:8]}"
VOLUME = f"{NAME}-data"
MAX_IMAGE_MB = 120
CHECKS = kit.Checks(stop_on_failure=True)
check = CHECKS.check


def docker(*args, check=True):
    out = subprocess.run(["docker", *args], capture_output=True, text=True)
    if check and out.returncode != 0:
        raise kit.Failure(f"docker {' '.join(args)}: {out.stderr.strip()}")
    return out.stdout.strip()


def request(base, method, path, body=None):
    """(status, the body as text): path answers are compared with the CLI's as text."""
    status, text, _ = kit.request(base, method, path, body, parse="text")
    return status, text


def wait_ready(base, seconds=30, container=NAME):
    """Until /readyz says ready (nothing degraded: the data directory is writable)."""
    try:
        kit.wait_until(f"{base}/readyz ready", lambda: kit.ready(base, timeout=60), seconds, interval=0.2)
    except kit.Timeout as e:
        raise kit.Timeout(f"{e}:\n{docker('logs', container, check=False)}") from None


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

        doc = kit.scenario("small-test", lambda d: d.update(name="container-test"))
        status, body = request(base, "POST", "/v1/scenarios", doc)
        check(status == 201, f"a scenario is registered ({status})")

        paper = kit.scenario_id(base, "paper-single-user")
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
        access = [json.loads(line) for line in logs.splitlines()
                  if line.startswith("{") and '"finished processing request"' in line]
        planned = [a for a in access if a.get("span", {}).get("route") == "/v1/paths"
                   and a.get("status") == 200 and a["span"].get("request_id") and a.get("latency")]
        check(planned, f"a JSON access-log line per answer (route template, status, latency, request "
                       f"id): {len(access)} lines, the last {access[-1] if access else None}")

        # The volume keeps the map: after a restart it answers without a build.
        docker("start", NAME)
        port = docker("port", NAME, "8080/tcp").splitlines()[0].rsplit(":", 1)[1]
        base = f"http://127.0.0.1:{port}"
        wait_ready(base)
        status, _ = request(base, "GET", f"/v1/maps/{map_id}")
        check(status == 200, "after a restart the map is served from the volume")
        status, again = request(base, "POST", "/v1/paths", path_request)
        check(untimed(again) == untimed(api_body), "and the same path is answered")
        check(kit.metric(base, "irs_map_builds_total") == 0, "without building it again")

        labels = json.loads(docker("image", "inspect", "--format", "{{json .Config.Labels}}", IMAGE)) or {}
        version = json.loads(request(base, "GET", "/version")[1])["version"]
        oci = {k.removeprefix("org.opencontainers.image."): v for k, v in labels.items()}
        check(oci.get("version") == version and oci.get("licenses") == "MIT" and oci.get("revision")
              and oci.get("title") == "irs-planner",
              f"OCI labels: version {oci.get('version')} (the server says {version}), "
              f"licence {oci.get('licenses')}, revision {oci.get('revision')}")
    finally:
        docker("rm", "-f", NAME, check=False)
        docker("volume", "rm", "-f", VOLUME, check=False)
    any_uid()


def any_uid():
    """An arbitrary uid in group 0 (OpenShift's way) writes the image's data directory: ready,
    not degraded, and a map it built is served after a restart without a build."""
    name, volume = f"{NAME}-uid", f"{NAME}-uid-data"
    docker("run", "-d", "--name", name, "--user", "12345:0", "-p", "127.0.0.1::8080",
           "-v", f"{volume}:/var/lib/irs-planner", IMAGE)
    try:
        base = lambda: "http://127.0.0.1:" + docker("port", name, "8080/tcp").splitlines()[0].rsplit(":", 1)[1]
        wait_ready(base(), container=name)
        check(docker("exec", name, "id", "-u") == "12345", "the server runs as uid 12345")
        small = kit.scenario_id(base(), "small-test")
        status, body = request(base(), "POST", "/v1/maps", {"scenario_id": small, "kind": "gain"})
        check(status == 200, f"a map built as uid 12345 ({status})")
        map_id = json.loads(body)["map_id"]
        docker("restart", "--time", "10", name)
        wait_ready(base(), container=name)
        status, _ = request(base(), "GET", f"/v1/maps/{map_id}")
        check(status == 200 and kit.metric(base(), "irs_map_builds_total") == 0,
              f"as uid 12345 the volume keeps the map across a restart ({status}, no build)")
    finally:
        docker("rm", "-f", name, check=False)
        docker("volume", "rm", "-f", volume, check=False)


if __name__ == "__main__":
    sys.exit(CHECKS.run(main))
