#!/usr/bin/env python3
"""deploy/kubernetes.yaml, checked as the API server and the kubelet would take it, offline.

    tests/deploy/kubernetes_check.py [deploy/kubernetes.yaml]

1. Every object against the Kubernetes OpenAPI schemas (`kubernetes-validate --strict`, which
   ships them: no cluster, no download), so a misspelt or misplaced field fails.
2. The rules a schema cannot express, which the API server or the kubelet enforce at apply or
   run time: a workload's selector matches its pod template's labels (else the apply is
   refused); every Service and PodDisruptionBudget selects pods some workload makes; a named
   `targetPort` or probe port is a port the container declares.
3. What the manifest says about irs-planner itself, against this checkout: every `IRS_*`
   variable is one the server reads (`crates/service/src/config.rs`), the probes ask paths
   the server answers (`openapi.yaml`), the termination grace covers the shutdown delay, the
   jobs' grace and the exit's last 2 s, and Redis's `maxmemory` is above the maps' budget with
   `noeviction` (docs/deployment.md, "Redis stays bounded").
Exits 1 naming every object and field that fails.
"""

import pathlib
import re
import subprocess
import sys

import yaml

ROOT = pathlib.Path(__file__).resolve().parents[2]
failures = []


def check(ok, what):
    print(("ok   " if ok else "FAIL ") + what, flush=True)
    if not ok:
        failures.append(what)


def name_of(obj):
    return f"{obj['kind']}/{obj['metadata']['name']}"


def containers(workload):
    return workload["spec"]["template"]["spec"]["containers"]


def matches(selector, labels):
    return all(labels.get(k) == v for k, v in selector.items())


def megabytes(text):
    """A Redis memory setting in MiB, with Redis's units (`1536mb`, `2gb`: powers of 1024;
    `1m`, `2g`: powers of 1000; plain bytes); None if it is not one."""
    found = re.fullmatch(r"(\d+)\s*([a-z]*)", str(text).lower())
    scale = {"": 1, "b": 1, "k": 1e3, "kb": 2**10, "m": 1e6, "mb": 2**20, "g": 1e9, "gb": 2**30}
    if not found or found.group(2) not in scale:
        return None
    return int(found.group(1)) * scale[found.group(2)] / 2**20


def mebibytes(quantity):
    """A Kubernetes memory quantity (`2Gi`, `512Mi`, `2G`, bytes) in MiB; None if not one."""
    found = re.fullmatch(r"(\d+)([KMGT]i?)?", str(quantity))
    if not found:
        return None
    scale = {None: 1, "Ki": 2**10, "Mi": 2**20, "Gi": 2**30, "Ti": 2**40,
             "K": 1e3, "M": 1e6, "G": 1e9, "T": 1e12}[found.group(2)]
    return int(found.group(1)) * scale / 2**20


def main():
    path = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ROOT / "deploy" / "kubernetes.yaml")
    validated = subprocess.run(["kubernetes-validate", "--strict", str(path)],
                               capture_output=True, text=True)
    if validated.returncode != 0:
        print(validated.stdout + validated.stderr, end="")
    check(validated.returncode == 0, "every object valid against the Kubernetes schemas (--strict)")

    objects = [o for o in yaml.safe_load_all(path.read_text()) if o]
    workloads = [o for o in objects if o["kind"] in ("Deployment", "StatefulSet")]
    for w in workloads:
        labels = w["spec"]["template"]["metadata"].get("labels", {})
        check(matches(w["spec"]["selector"]["matchLabels"], labels),
              f"{name_of(w)}: spec.selector matches the pod template's labels")
    pod_labels = [w["spec"]["template"]["metadata"].get("labels", {}) for w in workloads]
    for o in objects:
        selector = {"Service": lambda o: o["spec"].get("selector"),
                    "PodDisruptionBudget": lambda o: o["spec"]["selector"]["matchLabels"]}.get(o["kind"])
        if selector:
            check(any(matches(selector(o), labels) for labels in pod_labels),
                  f"{name_of(o)}: selects the pods of a workload here")
    for o in objects:
        if o["kind"] != "Service":
            continue
        targets = [w for w in workloads
                   if matches(o["spec"]["selector"], w["spec"]["template"]["metadata"]["labels"])]
        for port in o["spec"]["ports"]:
            target = port.get("targetPort", port["port"])
            declared = [p.get("name") if isinstance(target, str) else p["containerPort"]
                        for w in targets for c in containers(w) for p in c.get("ports", [])]
            check(target in declared, f"{name_of(o)}: targetPort {target} is a container port")
    for w in workloads:
        for c in containers(w):
            names = {p.get("name") for p in c.get("ports", [])}
            for probe in ("startupProbe", "livenessProbe", "readinessProbe"):
                port = c.get(probe, {}).get("httpGet", {}).get("port")
                if isinstance(port, str):
                    check(port in names, f"{name_of(w)}: {probe} port {port!r} is declared")

    # irs-planner itself.
    config = (ROOT / "crates/service/src/config.rs").read_text()
    known = set(re.findall(r'env = "(IRS_[A-Z0-9_]+)"', config))
    openapi = yaml.safe_load((ROOT / "openapi.yaml").read_text())
    planner = next(w for w in workloads if w["metadata"]["name"] == "irs-planner")
    (container,) = containers(planner)
    env = {e["name"]: e.get("value") for e in container.get("env", [])}
    for name in env:
        if name.startswith("IRS_"):
            check(name in known, f"{name_of(planner)}: {name} is a setting the server reads")
    for probe in ("startupProbe", "livenessProbe", "readinessProbe"):
        probe_path = container[probe]["httpGet"]["path"]
        check(probe_path in openapi["paths"], f"{name_of(planner)}: {probe} asks {probe_path}, a route")
    check(container["readinessProbe"]["httpGet"]["path"] == "/readyz"
          and container["livenessProbe"]["httpGet"]["path"] == "/healthz",
          f"{name_of(planner)}: routed on /readyz, restarted on /healthz only (a Redis outage "
          f"restarts nothing)")
    default = lambda flag: int(re.search(rf'env = "{flag}", default_value_t = (\d+)', config).group(1))
    delay = int(env.get("IRS_SHUTDOWN_DELAY_S") or default("IRS_SHUTDOWN_DELAY_S"))
    grace = int(env.get("IRS_SHUTDOWN_GRACE_S") or default("IRS_SHUTDOWN_GRACE_S"))
    termination = planner["spec"]["template"]["spec"].get("terminationGracePeriodSeconds", 30)
    check(delay + grace + 2 <= termination,
          f"{name_of(planner)}: terminationGracePeriodSeconds {termination} covers the delay {delay} s, "
          f"the jobs' grace {grace} s and 2 s to exit")
    check(delay >= 1, f"{name_of(planner)}: a shutdown delay ({delay} s) while endpoints are removed")
    security = planner["spec"]["template"]["spec"].get("securityContext", {})
    check(security.get("runAsNonRoot") is True and security.get("runAsGroup", 0) == 0,
          f"{name_of(planner)}: non-root, group 0 (the image's data directory is group 0's)")
    mounts = [m["mountPath"] for m in container.get("volumeMounts", [])]
    if container.get("securityContext", {}).get("readOnlyRootFilesystem"):
        check("/var/lib/irs-planner" in mounts,
              f"{name_of(planner)}: a read-only root with the data directory mounted writable")

    redis = next(w for w in workloads if w["metadata"]["name"] == "redis")
    args = containers(redis)[0].get("args", [])
    setting = lambda flag: args[args.index(flag) + 1] if flag in args else None
    budget = int(env.get("IRS_REDIS_MAPS_MB") or default("IRS_REDIS_MAPS_MB"))
    maxmemory = setting("--maxmemory")
    max_mib = megabytes(maxmemory) if maxmemory is not None else None
    check(max_mib is not None and max_mib > budget,
          f"{name_of(redis)}: maxmemory {maxmemory} above the maps' budget of {budget} MiB")
    check(setting("--maxmemory-policy") == "noeviction",
          f"{name_of(redis)}: maxmemory-policy noeviction (Redis evicting a lock or a job record "
          f"breaks the cluster)")
    limit = containers(redis)[0].get("resources", {}).get("limits", {}).get("memory", "")
    limit_mib = mebibytes(limit)
    # An append-only-file rewrite forks Redis: its copy-on-write pages need room beyond
    # maxmemory, or the kernel kills it mid-rewrite. Half as much again is the usual margin.
    check(limit_mib is not None and max_mib is not None and max_mib * 1.5 <= limit_mib,
          f"{name_of(redis)}: its memory limit ({limit}) at least 1.5 x maxmemory (room for a "
          f"rewrite's fork; else it is killed, not full)")

    if failures:
        print(f"{len(failures)} check(s) failed", file=sys.stderr)
        sys.exit(1)
    print("deploy/kubernetes.yaml: every check passed")


if __name__ == "__main__":
    main()
