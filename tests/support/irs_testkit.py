"""What the Python suites under tests/ share (standard library only).

A suite finds this module through its own location:

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "support"))
    import irs_testkit as kit

* `Checks`: counts checks, prints `ok   NAME` or `FAIL NAME: DETAIL` for each and, at the end,
  `N passed, M failed` alone on a line; the exit code is 1 when anything failed.
* `Server`: `irs-planner serve --bind 127.0.0.1:0 ...` started, its `listening on URL` line read
  within a timeout; stopped with SIGTERM, then SIGKILL of its process group. Every process
  started here (`spawn`) runs in a process group of its own, killed when the suite exits.
* `request`/`get`/`post`/`delete`: JSON over HTTP, answering `Response(status, body, headers)`
  for every status (no exception for 4xx/5xx unless asked); `problem_mismatch` checks an
  RFC 9457 problem+json answer (status, media type, the field it names).
* `wait_until`, `wait_job`: bounded waits; a timeout raises `Timeout` (an AssertionError).
* `free_port`, `metric`, `ready`, `scenario`, `scenario_id`.
"""

import atexit
import json
import os
import queue
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import traceback
import urllib.error
import urllib.request
from typing import Any, NamedTuple

# The repository (tests/support/ is two levels below it).
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

FINAL_JOB_STATES = ("done", "failed", "cancelled")


class Failure(AssertionError):
    """A step of a suite failed (the message says which)."""


class CheckFailed(Failure):
    """A check failed in a suite that stops at its first failure (already counted and printed)."""


class Timeout(Failure):
    """A bounded wait ran out."""


# ------------------------------------------------------------------------------------ checks


class Checks:
    """Counts checks. With `stop_on_failure`, a failed check raises `CheckFailed` (for suites
    whose later steps need the earlier ones); otherwise the suite goes on and `finish` exits 1."""

    def __init__(self, stop_on_failure=False):
        self.stop_on_failure = stop_on_failure
        self.passed = 0
        self.failed = 0

    def check(self, condition, name, detail=""):
        """Counts and prints one check; returns whether it passed."""
        ok = bool(condition)
        detail = "" if detail is None else str(detail)
        print(("ok   " if ok else "FAIL ") + name + (f": {detail}" if detail else ""), flush=True)
        if ok:
            self.passed += 1
        else:
            self.failed += 1
            if self.stop_on_failure:
                raise CheckFailed(name)
        return ok

    def fail(self, name, detail=""):
        """A failed check (always raises `CheckFailed` with `stop_on_failure`)."""
        return self.check(False, name, detail)

    def summary(self):
        """Prints `N passed, M failed` alone on a line; returns the exit code (0 or 1)."""
        print(f"{self.passed} passed, {self.failed} failed", flush=True)
        return 1 if self.failed else 0

    def finish(self):
        """The summary line, then exit (1 if anything failed)."""
        sys.exit(self.summary())

    def run(self, main):
        """Runs `main()`, counts a failed step (a timeout, an error) as a failed check, prints the
        summary; returns the exit code. SystemExit and KeyboardInterrupt go through."""
        try:
            main()
        except CheckFailed:
            pass
        except AssertionError as e:
            self._count_failure(str(e) or type(e).__name__, "")
        except Exception as e:  # an unexpected error: its traceback, and a failure
            traceback.print_exc()
            self._count_failure("the suite stopped on an error", repr(e))
        return self.summary()

    def _count_failure(self, name, detail):
        try:
            self.fail(name, detail)
        except CheckFailed:
            pass


# --------------------------------------------------------------------------------- processes

_PROCESSES = []
_LOCK = threading.Lock()
_SIGNALS_HOOKED = False


def _exit_on_signal(signum, _frame):
    raise SystemExit(128 + signum)


def _hook_signals():
    """SIGTERM and SIGHUP end the suite through SystemExit, so that `finally` blocks and the
    exit hook below stop what it started (their default action would skip both)."""
    global _SIGNALS_HOOKED
    if _SIGNALS_HOOKED or threading.current_thread() is not threading.main_thread():
        return
    _SIGNALS_HOOKED = True
    for signum in (signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(signum) == signal.SIG_DFL:
            signal.signal(signum, _exit_on_signal)


def spawn(args, **popen):
    """`subprocess.Popen(args, **popen)` in a new session (its own process group), killed at
    the latest when this interpreter exits."""
    _hook_signals()
    proc = subprocess.Popen(args, start_new_session=True, **popen)
    with _LOCK:
        _PROCESSES.append(proc)
    return proc


def stop_process(proc, timeout=10.0):
    """SIGTERM, up to `timeout` seconds for it to exit, then SIGKILL of its process group."""
    if proc.poll() is None:
        try:
            proc.terminate()
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            pass
    kill_process(proc)


def kill_process(proc):
    """SIGKILL of the process group of a process started by `spawn` (what the process itself
    started too, even once it has exited), and the process reaped."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    if proc.poll() is None:
        proc.kill()
    proc.wait()


def stop_all():
    """Kills (SIGKILL) every process group started by `spawn` that still runs."""
    with _LOCK:
        processes = list(_PROCESSES)
    for proc in processes:
        try:
            kill_process(proc)
        except Exception:  # at exit: stop the others regardless
            pass


atexit.register(stop_all)


def free_port():
    """A TCP port free on 127.0.0.1 at the time of asking."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """`BINARY serve --bind 127.0.0.1:0 FLAGS...`, started and listening.

    `base` is the URL of its `listening on URL` line, read within `start_timeout` seconds;
    stderr goes to `log_path` (a new temporary file unless given); `timeout` is the default
    HTTP timeout of its request helpers. Stop with `stop()` (or leave it to the exit hook)."""

    def __init__(self, binary, *flags, log_path=None, env=None, timeout=60, start_timeout=30):
        if log_path is None:
            with tempfile.NamedTemporaryFile(prefix="irs-server-", suffix=".log", delete=False) as f:
                log_path = f.name
        self.log_path = log_path
        self.timeout = timeout
        self.stdout = []  # what it printed on stdout after the listening line
        with open(log_path, "w") as log:
            self.proc = spawn([binary, "serve", "--bind", "127.0.0.1:0", *flags],
                              stdout=subprocess.PIPE, stderr=log, text=True, env=env)
        lines = queue.Queue()
        threading.Thread(target=self._read_stdout, args=(lines,), daemon=True).start()
        try:
            line = lines.get(timeout=start_timeout)
        except queue.Empty:
            line = None
        if not line or not line.startswith("listening on "):
            self.stop(timeout=2)
            said = "nothing" if line is None else repr(line)
            raise Failure(f"{binary} serve did not start within {start_timeout} s "
                          f"(its stdout said {said}; exit code {self.proc.returncode}): "
                          f"{self.log_tail(5)}")
        self.base = line.split()[-1]
        self.port = int(self.base.rsplit(":", 1)[1])

    def _read_stdout(self, lines):
        # Reads stdout to its end, so that the server never blocks on a full pipe.
        first = True
        try:
            for line in self.proc.stdout:
                if first:
                    lines.put(line)
                    first = False
                else:
                    self.stdout.append(line)
        except (OSError, ValueError):
            pass
        if first:
            lines.put("")

    def log_text(self):
        with open(self.log_path, errors="replace") as f:
            return f.read()

    def log_tail(self, lines=15):
        return "".join(self.log_text().splitlines(keepends=True)[-lines:])

    def request(self, method, path, body=None, **kw):
        kw.setdefault("timeout", self.timeout)
        return request(self.base, method, path, body, **kw)

    def get(self, path, **kw):
        return self.request("GET", path, **kw)

    def post(self, path, body, **kw):
        return self.request("POST", path, body, **kw)

    def delete(self, path, **kw):
        return self.request("DELETE", path, **kw)

    def metric(self, name):
        return metric(self.base, name)

    def wait_job(self, job_id, seconds=120, **kw):
        return wait_job(self.base, job_id, seconds, **kw)

    def running(self):
        return self.proc.poll() is None

    def stop(self, timeout=10.0):
        """SIGTERM (the server drains, within its grace period plus 2 s), then SIGKILL of its
        process group after `timeout` seconds."""
        stop_process(self.proc, timeout)


# -------------------------------------------------------------------------------------- HTTP


class Response(NamedTuple):
    status: int
    body: Any  # JSON; the text if it is not JSON (or with parse="text"); bytes with parse="bytes"
    headers: dict  # lower-case names


def request(base, method, path, body=None, *, token=None, headers=None, timeout=60,
            parse="json", raise_for_status=False):
    """`method base+path` with `body` as JSON (bytes are sent as they are, as JSON), a bearer
    `token` if given. Answers every status as a Response; `raise_for_status` makes a status
    outside 2xx a `Failure` naming the request and its answer. Connection errors and timeouts
    raise (OSError)."""
    sent = {} if headers is None else dict(headers)
    data = None
    if body is not None:
        data = body if isinstance(body, (bytes, bytearray)) else json.dumps(body).encode()
        sent.setdefault("content-type", "application/json")
    if token:
        sent["authorization"] = f"Bearer {token}"
    req = urllib.request.Request(base + path, data, sent, method=method)
    try:
        with urllib.request.urlopen(req, timeout=timeout) as resp:
            status, raw, received = resp.status, resp.read(), resp.headers
    except urllib.error.HTTPError as e:
        status, raw, received = e.code, e.read(), e.headers
    answer = Response(status, _decode(raw, parse), {k.lower(): v for k, v in received.items()})
    if raise_for_status and not 200 <= status < 300:
        raise Failure(f"{method} {path}: {status} {str(answer.body)[:300]}")
    return answer


def _decode(raw, parse):
    if parse == "bytes":
        return raw
    text = raw.decode(errors="replace")
    if parse == "text":
        return text
    if not raw.strip():
        return None
    try:
        return json.loads(raw)
    except ValueError:
        return text


def get(base, path, **kw):
    return request(base, "GET", path, **kw)


def post(base, path, body, **kw):
    return request(base, "POST", path, body, **kw)


def delete(base, path, **kw):
    return request(base, "DELETE", path, **kw)


def problem_mismatch(response, status, field=None, code=None):
    """What is wrong with `response` as an RFC 9457 problem+json answer of `status`: "" if
    nothing. `field`: True for "names a field", a string for that field; `code`: its code."""
    got, body, headers = response
    wrong = []
    if got != status:
        wrong.append(f"status {got}, not {status}")
    media = headers.get("content-type", "").split(";")[0].strip()
    if media != "application/problem+json":
        wrong.append(f"content-type {media!r}, not application/problem+json")
    if not isinstance(body, dict):
        wrong.append("the body is not a JSON object")
    else:
        if field is True and not body.get("field"):
            wrong.append("the problem names no field")
        elif isinstance(field, str) and body.get("field") != field:
            wrong.append(f"field {body.get('field')!r}, not {field!r}")
        if code is not None and body.get("code") != code:
            wrong.append(f"code {body.get('code')!r}, not {code!r}")
    return "; ".join(wrong) + (f" ({str(body)[:300]})" if wrong else "")


def metric(base, name, timeout=10):
    """The sum of the /metrics samples of `name` (over its labels)."""
    with urllib.request.urlopen(base + "/metrics", timeout=timeout) as resp:
        text = resp.read().decode()
    total = 0.0
    for line in text.splitlines():
        if line.startswith(name) and (len(line) == len(name) or line[len(name)] in " {"):
            total += float(line.rsplit(" ", 1)[1])
    return total


def ready(base, timeout=5):
    """Whether /readyz answers 200 `ready`: started, and nothing degraded (a replica not yet
    connected to its Redis is degraded, and would refuse what needs it)."""
    answer = get(base, "/readyz", timeout=timeout)
    return answer.status == 200 and isinstance(answer.body, dict) and answer.body.get("status") == "ready"


# ------------------------------------------------------------------------------------- waits


def wait_until(what, predicate, seconds, interval=0.1):
    """Polls `predicate` until it returns something true (returned), for at most `seconds`;
    a connection error (OSError) counts as not yet. Raises `Timeout` naming `what`."""
    deadline = time.monotonic() + seconds
    last_error = None
    while True:
        try:
            value = predicate()
            if value:
                return value
        except OSError as e:
            last_error = e
        if time.monotonic() >= deadline:
            break
        time.sleep(interval)
    raise Timeout(f"{what}: not within {seconds} s"
                  + (f" (last error: {last_error!r})" if last_error else ""))


def wait_job(base, job_id, seconds=120, interval=0.05, token=None):
    """GET /v1/jobs/ID until its state is final (done, failed or cancelled), for at most
    `seconds`: the job. Raises `Timeout` with the last state seen."""
    seen = {}

    def final():
        status, job, _ = get(base, f"/v1/jobs/{job_id}", token=token)
        seen["answer"] = (status, job)
        return status == 200 and job["state"] in FINAL_JOB_STATES

    try:
        wait_until(f"job {job_id} in a final state", final, seconds, interval)
    except Timeout as e:
        raise Timeout(f"{e}; last answer {seen.get('answer')}") from None
    return seen["answer"][1]


# --------------------------------------------------------------------------------- scenarios


def scenario(name, edit=None):
    """scenarios/NAME.json as a dict, changed by `edit(doc)` if given."""
    with open(os.path.join(ROOT, "scenarios", f"{name}.json")) as f:
        doc = json.load(f)
    if edit:
        edit(doc)
    return doc


def scenario_id(base, name, **kw):
    """The id of the scenario a server lists under `name`."""
    listed = get(base, "/v1/scenarios?limit=1000", raise_for_status=True, **kw).body["scenarios"]
    return next(s["id"] for s in listed if s["name"] == name)
