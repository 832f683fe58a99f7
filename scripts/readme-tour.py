#!/usr/bin/env python3
"""Run the README's shell blocks, in order, against a running irs-planner server.

Usage:
    python3 scripts/readme-tour.py --binary PATH --url URL [README.md]
    python3 scripts/readme-tour.py --list [--url URL] [README.md]

Options: --block-timeout S (default 300), --keep (keep the working directory), --verbose (show
the output of passing blocks too).

Convention (docs/architecture.md, "The README tour"):

* A fenced code block whose info string is ``sh`` (```sh) is a tour block and is run. Blocks
  tagged anything else (``json``, ``console``, ``text``, none) are never run.
* A ``sh`` block that cannot run in CI (cargo, docker, apt-get, a server of its own) is
  excluded by the HTML comment ``<!-- tour: skip -->`` (optionally with a reason:
  ``<!-- tour: skip (needs docker) -->``) as the last non-blank line before its opening fence.
  The comment does not show when the Markdown is rendered.
* The blocks are written for a reader whose server runs on ``localhost:8080`` and who stands
  in a checkout's root. The harness therefore
  - replaces ``localhost:8080`` and ``127.0.0.1:8080`` (with or without ``http://``) by --url;
  - exports ``BASE`` = --url, for a block that wants to name the server explicitly;
  - puts a directory holding ``irs-planner`` (a link to --binary) first on PATH;
  - runs in a fresh temporary directory holding a copy of the checkout's ``scenarios/``
    (the directory next to the README), so ``--scenario scenarios/...`` resolves and the files
    the tour writes (PNGs, masks, tars) do not land in the checkout;
  - makes ``curl`` fail on an HTTP error status (an alias adding ``--fail-with-body
    --show-error``): a 4xx or 5xx answer fails the block and its body is shown.
* All blocks run in one ``bash`` process under ``set -euo pipefail``, so variables set by one
  block (``SID``, ``J``) are seen by the next; the first failing command stops the tour.

Exit status 0 when every run block passed, 1 when one failed (its README line, the failing
line and the block's output are printed), 2 for a usage error. The last line printed is
``N passed, M failed`` alone (the line before it counts blocks skipped by marker and blocks not
run after a failure), as the Python suites under tests/ end.

Standard library only.
"""

from __future__ import annotations

import argparse
import os
import queue
import re
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from dataclasses import dataclass

RUN_TAG = "sh"
SKIP_RE = re.compile(r"^\s*<!--\s*tour:\s*skip\b.*-->\s*$")
FENCE_RE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})\s*(?P<info>[^`]*)$")
SERVER_RE = re.compile(r"(?:https?://)?(?:localhost|127\.0\.0\.1):8080")
SHOWN_OUTPUT_LINES = 120


@dataclass
class Block:
    line: int  # 1-based line of the opening fence
    tag: str
    lines: list[str]  # the block's text, one entry per README line (first is line + 1)
    skip: bool

    @property
    def first_line(self) -> int:
        return self.line + 1


def parse_blocks(text: str) -> list[Block]:
    """Every fenced code block of the Markdown text (nested fences are not a thing in it)."""
    blocks: list[Block] = []
    lines = text.splitlines()
    i = 0
    last_nonblank = ""
    while i < len(lines):
        m = FENCE_RE.match(lines[i])
        if not m:
            if lines[i].strip():
                last_nonblank = lines[i]
            i += 1
            continue
        fence = m.group("fence")
        tag = (m.group("info").split() or [""])[0]
        start = i
        body: list[str] = []
        i += 1
        while i < len(lines):
            close = lines[i].strip()
            if close and set(close) == {fence[0]} and len(close) >= len(fence):
                break
            body.append(lines[i])
            i += 1
        blocks.append(Block(start + 1, tag, body, bool(SKIP_RE.match(last_nonblank))))
        last_nonblank = ""
        i += 1  # past the closing fence
    return blocks


def substitute(line: str, url: str | None) -> str:
    return SERVER_RE.sub(url.rstrip("/"), line) if url else line


def build_script(blocks: list[Block], url: str | None, token: str) -> tuple[str, dict[int, int]]:
    """The bash script of the run blocks, and a map from script line to README line."""
    prelude = [
        "set -euo pipefail",
        "shopt -s expand_aliases",
        "alias curl='curl --fail-with-body --show-error'",
        f"__tour={token}",
        # A failing command names its script line and status before errexit ends the shell.
        'trap \'__tour_status=$?; printf "\\n%s err %s %s\\n" "$__tour" "$LINENO" '
        '"$__tour_status"\' ERR',
    ]
    script = list(prelude)
    line_map: dict[int, int] = {}
    for n, block in enumerate(blocks):
        script.append(f'printf "\\n%s begin {n}\\n" "$__tour"')
        for k, text in enumerate(block.lines):
            script.append(substitute(text, url))
            line_map[len(script)] = block.first_line + k
        # A block that ends inside an unterminated quote or heredoc would swallow the marker;
        # bash then fails with a syntax error at the end of the script, reported on this block.
        script.append(f'printf "\\n%s end {n}\\n" "$__tour"')
    return "\n".join(script) + "\n", line_map


def wait_for_server(url: str, seconds: float) -> str | None:
    """None once GET {url}/healthz answers 200, else the last error."""
    deadline = time.monotonic() + seconds
    error = "no answer"
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(url.rstrip("/") + "/healthz", timeout=2) as answer:
                if answer.status == 200:
                    return None
                error = f"status {answer.status}"
        except (urllib.error.URLError, OSError) as e:
            error = str(e)
        time.sleep(0.2)
    return error


def reader(stream, lines: queue.Queue) -> None:
    for raw in iter(stream.readline, b""):
        lines.put(raw.decode("utf-8", "replace"))
    lines.put(None)


def show_tail(output: str) -> None:
    text = output.strip("\n")
    if not text:
        print("    (no output)")
        return
    rows = text.splitlines()
    if len(rows) > SHOWN_OUTPUT_LINES:
        print(f"    … {len(rows) - SHOWN_OUTPUT_LINES} earlier lines not shown")
        rows = rows[-SHOWN_OUTPUT_LINES:]
    for row in rows:
        print("    | " + (row if len(row) <= 400 else row[:400] + " …"))


def list_blocks(readme: str, blocks: list[Block], url: str | None) -> None:
    for block in blocks:
        if block.tag != RUN_TAG:
            continue
        state = "skip" if block.skip else "run "
        print(f"--- {state} {readme}:{block.line}")
        for text in block.lines:
            print("    " + substitute(text, url))
    runs = [b for b in blocks if b.tag == RUN_TAG]
    skipped = sum(b.skip for b in runs)
    print(f"{len(runs) - skipped} blocks to run, {skipped} skipped by marker")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("readme", nargs="?", default=None, help="the Markdown file (default: README.md of the checkout)")
    parser.add_argument("--binary", help="the irs-planner binary the CLI lines run")
    parser.add_argument("--url", help="the running server, e.g. http://127.0.0.1:34567")
    parser.add_argument("--list", action="store_true", help="print the blocks that would run, run nothing")
    parser.add_argument("--block-timeout", type=float, default=300, help="seconds one block may take (default 300)")
    parser.add_argument("--keep", action="store_true", help="keep the temporary working directory")
    parser.add_argument("--verbose", action="store_true", help="also print the output of blocks that pass")
    args = parser.parse_args()

    checkout = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    readme = args.readme or os.path.join(checkout, "README.md")
    try:
        with open(readme, encoding="utf-8") as f:
            blocks = parse_blocks(f.read())
    except OSError as e:
        print(f"readme-tour: {e}", file=sys.stderr)
        return 2
    shown = os.path.relpath(readme)

    if args.list:
        list_blocks(shown, blocks, args.url)
        return 0
    if not args.binary or not args.url:
        parser.error("--binary and --url are needed (or --list)")
    binary = os.path.abspath(args.binary)
    if not (os.path.isfile(binary) and os.access(binary, os.X_OK)):
        print(f"readme-tour: {binary} is not an executable file", file=sys.stderr)
        return 2
    problem = wait_for_server(args.url, 10)
    if problem:
        print(f"readme-tour: {args.url}/healthz does not answer 200: {problem}", file=sys.stderr)
        return 2

    runs = [b for b in blocks if b.tag == RUN_TAG and not b.skip]
    skipped = sum(1 for b in blocks if b.tag == RUN_TAG and b.skip)
    token = "__readme_tour_" + secrets.token_hex(8)
    script, line_map = build_script(runs, args.url, token)

    work = tempfile.mkdtemp(prefix="readme-tour-")
    try:
        scenarios = os.path.join(os.path.dirname(os.path.abspath(readme)), "scenarios")
        if os.path.isdir(scenarios):
            shutil.copytree(scenarios, os.path.join(work, "scenarios"), symlinks=True)
        bindir = os.path.join(work, ".tour-bin")
        os.mkdir(bindir)
        os.symlink(binary, os.path.join(bindir, "irs-planner"))
        script_path = os.path.join(work, ".tour.sh")
        with open(script_path, "w", encoding="utf-8") as f:
            f.write(script)
        env = dict(os.environ)
        env["PATH"] = bindir + os.pathsep + env.get("PATH", "")
        env["BASE"] = args.url.rstrip("/")
        result = run(script_path, work, env, token, runs, line_map, shown, args.block_timeout, args.verbose)
    finally:
        if args.keep:
            print(f"working directory kept: {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)

    passed, failed = result
    not_run = len(runs) - passed - failed
    extra = []
    if not_run:
        extra.append(f"{not_run} not run after the failure")
    if skipped:
        extra.append(f"{skipped} skipped by marker")
    if extra:
        print("blocks: " + ", ".join(extra))
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


def run(script_path, work, env, token, runs, line_map, shown, block_timeout, verbose) -> tuple[int, int]:
    process = subprocess.Popen(
        ["bash", script_path], cwd=work, env=env, stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
    )
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=reader, args=(process.stdout, lines), daemon=True).start()

    passed = 0
    current: int | None = None  # index of the block running
    started = time.monotonic()
    output: list[str] = []
    failed_line: int | None = None
    failed_status: str | None = None
    timed_out = False
    eof = False
    while not eof:
        try:
            item = lines.get(timeout=0.5)
        except queue.Empty:
            if current is not None and time.monotonic() - started > block_timeout:
                timed_out = True
                os.killpg(process.pid, signal.SIGKILL)
                break
            continue
        if item is None:
            eof = True
            break
        if item.startswith(token + " "):
            _, what, *rest = item.split()
            if what == "begin":
                current, started, output = int(rest[0]), time.monotonic(), []
            elif what == "end":
                block = runs[int(rest[0])]
                print(f"PASS {shown}:{block.line} ({time.monotonic() - started:.1f} s)")
                if verbose:
                    show_tail("".join(output))
                passed += 1
                current = None
            elif what == "err":
                failed_line, failed_status = line_map.get(int(rest[0])), rest[1]
            continue
        output.append(item)
    code = process.wait()
    # Output after the last marker that is not a failure of a block: a syntax error or a failure
    # outside every block.
    if current is None and code == 0 and not timed_out:
        return passed, 0
    index = current if current is not None else min(passed, len(runs) - 1)
    block = runs[index] if runs else None
    where = f"{shown}:{block.line}" if block else shown
    if timed_out:
        why = f"timed out after {block_timeout:.0f} s"
    else:
        why = f"exit status {failed_status or code}"
    print(f"FAIL {where} ({why})")
    if failed_line is not None:
        readme_lines = open_readme_line(shown, failed_line)
        print(f"  failing command near {shown}:{failed_line}: {readme_lines}")
    if block:
        print("  block:")
        for k, text in enumerate(block.lines):
            print(f"    {block.first_line + k:4} {text}")
    print("  output:")
    show_tail("".join(output))
    return passed, 1


def open_readme_line(path: str, number: int) -> str:
    try:
        with open(path, encoding="utf-8") as f:
            for k, text in enumerate(f, 1):
                if k == number:
                    return text.strip()
    except OSError:
        pass
    return ""


if __name__ == "__main__":
    sys.exit(main())
