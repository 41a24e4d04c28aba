"""First run: from a fresh clone to a live dashboard with ``make run``, as a new user
starts the project (package caches warm, nothing else prepared).

Each repeat clones the repository's committed HEAD into a temporary directory (no venv,
no ``node_modules``, no built dashboard, no numba cache), runs ``make run`` there on free
ports, and records when, counted from the start of ``make run``:

- each ``[setup]``/``[run]`` step began (the lines the Makefile prints),
- ``/api/health`` first answered,
- ``/`` served the dashboard's page (``<div id="app">``),
- the first live frame arrived (``/api/pose/latest`` answered: frames stream),
- the first pose with ``ok`` true arrived, and which implementation of the pipeline gave
  it (``/api/health`` -> ``pipeline.implementation`` read after the pose: the server
  measures with the reference implementation while the kernels compile, and only ever
  switches from it to the compiled one, so "reference" then means the pose was its),
- the pipeline's kernels were ready (``/api/health`` -> ``pipeline.state``),
- the first pose of the compiled implementation (``pipeline.implementation``).

"Dashboard live" is the later of the page and the first frame. While the reference
implementation measures, it also records the pipeline's time of each pose seen
(``timings_ms.total``) and the delivered frame rate (``/api/devices``). Medians over
repeats. The goal of a first pose in 30 s is counted from the server's start (the
``[run] starting the server`` line), after the venv and the dashboard are built.

Run: ``python bench/first_run.py [--repeats 3] [--timeout 400] [--readme]``
(``--readme``: also write the tables into README.md between its first-run markers).
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import all_cores, table  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MILESTONES = (
    "health",
    "dashboard",
    "first frame",
    "dashboard live",
    "first ok pose",
    "kernels ready",
    "compiled poses",
)
SERVER_STEP = "starting the server"
#: seconds from the server's start to the first ok pose (issue 47)
FIRST_POSE_GOAL_S = 30.0


@dataclass
class Run:
    """One fresh clone's ``make run``: milestone -> s, make step -> s (both from its
    start), which implementation gave the first ok pose, and the reference pipeline's
    ms per pose and the delivered frames/s while it measured."""

    seen: dict[str, float] = field(default_factory=dict)
    steps: dict[str, float] = field(default_factory=dict)
    first_pose_by: str = ""
    reference_ms: list[float] = field(default_factory=list)
    reference_rate_hz: list[float] = field(default_factory=list)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _read_output(proc: subprocess.Popen, t0: float, steps: dict[str, float], log: list[str]):
    """Timestamp each ``[setup] ...`` / ``[run] ...`` line of make's output."""
    for line in proc.stdout:  # type: ignore[union-attr]
        log.append(line.rstrip())
        m = re.match(r"\[(setup|run)\] (.{0,60})", line)
        if m:
            steps.setdefault(m.group(2).split("(")[0].strip(), time.monotonic() - t0)


def one_run(timeout_s: float) -> Run:
    """One fresh clone's ``make run`` (``Run``)."""
    with tempfile.TemporaryDirectory(prefix="tofpose-first-run-") as tmp:
        clone = Path(tmp) / "tofpose"
        subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True)
        port = free_port()
        env = {**os.environ, "TOFPOSE_PORT": str(port), "TOFPOSE_VISER_PORT": str(free_port())}
        env.pop("VIRTUAL_ENV", None)
        t0 = time.monotonic()
        proc = subprocess.Popen(
            ["make", "run"],
            cwd=clone,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )
        run = Run()
        log: list[str] = []
        reader = threading.Thread(target=_read_output, args=(proc, t0, run.steps, log), daemon=True)
        reader.start()
        seen = run.seen
        base = f"http://127.0.0.1:{port}"
        try:
            with httpx.Client(timeout=2.0) as client:
                while len(seen) < len(MILESTONES) and time.monotonic() - t0 < timeout_s:
                    if proc.poll() is not None:
                        raise RuntimeError("make run exited:\n" + "\n".join(log[-30:]))
                    _poll(client, base, run, t0)
                    time.sleep(0.2)
        finally:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
        if len(seen) < len(MILESTONES):
            missing = [m for m in MILESTONES if m not in seen]
            raise RuntimeError(f"not reached within {timeout_s:g} s: {missing}")
        return run


def _implementation(client: httpx.Client, base: str) -> str | None:
    return client.get(base + "/api/health").json()["pipeline"].get("implementation")


def _poll(client: httpx.Client, base: str, run: Run, t0: float) -> None:
    seen = run.seen
    now = time.monotonic() - t0
    try:
        h = client.get(base + "/api/health").json()
    except (httpx.HTTPError, ValueError):
        return
    seen.setdefault("health", now)
    pipeline = h.get("pipeline", {})
    before = pipeline.get("implementation")
    if pipeline.get("state") == "ready":
        seen.setdefault("kernels ready", now)
    if before == "compiled":
        seen.setdefault("compiled poses", now)
    if "dashboard" not in seen and '<div id="app">' in client.get(base + "/").text:
        seen["dashboard"] = now
    r = client.get(base + "/api/pose/latest")
    if r.status_code == 200:
        seen.setdefault("first frame", now)
        pose = r.json()
        if pose.get("ok") and "first ok pose" not in seen:
            seen["first ok pose"] = now
            after = _implementation(client, base)  # reference -> compiled, never back
            run.first_pose_by = (
                after
                if after == "reference" or before == after
                else "reference or compiled (switched meanwhile)"
            )
        if pose.get("ok") and before == "reference":
            run.reference_ms.append(pose["timings_ms"]["total"])
            rate = client.get(base + "/api/devices").json()["camera"]["frame_rate_hz"]
            run.reference_rate_hz.append(rate)
    if "dashboard" in seen and "first frame" in seen:
        seen.setdefault("dashboard live", max(seen["dashboard"], seen["first frame"]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--timeout", type=float, default=400.0, help="s per run")
    ap.add_argument("--readme", action="store_true", help="write the result into README.md")
    args = ap.parse_args()
    all_cores()
    runs = []
    for _ in tqdm(range(args.repeats), desc="fresh clones", unit="run"):
        runs.append(one_run(args.timeout))
    text = summary(runs)
    print("\n" + text)
    if args.readme:
        write_readme(text)


def summary(runs: list[Run]) -> str:
    """The milestone and step tables, the reference pipeline's pace and the verdicts,
    as Markdown."""
    rows = [
        [m, f"{np.median([r.seen[m] for r in runs]):.1f}", f"{max(r.seen[m] for r in runs):.1f}"]
        for m in MILESTONES
    ]
    names = sorted(
        {k for r in runs for k in r.steps},
        key=lambda k: np.median([r.steps.get(k, 0) for r in runs]),
    )
    steps = [[n, f"{np.median([r.steps[n] for r in runs if n in r.steps]):.1f}"] for n in names]
    live = np.median([r.seen["dashboard live"] for r in runs])
    pose = np.median([r.seen["first ok pose"] for r in runs])
    after_start = np.median([r.seen["first ok pose"] - r.steps[SERVER_STEP] for r in runs])
    after_start_max = max(r.seen["first ok pose"] - r.steps[SERVER_STEP] for r in runs)
    by = ", ".join(sorted({r.first_pose_by for r in runs}))
    ms = [v for r in runs for v in r.reference_ms]
    hz = [v for r in runs for v in r.reference_rate_hz]
    pace = (
        f"While the kernels compiled, the reference implementation took {np.median(ms):.0f} ms "
        f"a pose (median of {len(ms)} seen; 95th percentile {np.percentile(ms, 95):.0f} ms) "
        f"and the camera delivered {np.median(hz):.1f} frames/s (median; set to 10)."
        if ms
        else "No reference pose was seen while the kernels compiled."
    )
    return "\n".join(
        [
            f"Fresh clone -> `make run`, seconds from its start, {len(runs)} runs (median and "
            "max), package caches warm:",
            "",
            table(["milestone", "median s", "max s"], rows),
            "",
            "when each step of `make run` began (median s):",
            "",
            table(["step", "began at s"], steps),
            "",
            f"Dashboard live (the later of `/` serving the page and the first live frame) after "
            f"{live:.1f} s: the <= 60 s goal is {'met' if live <= 60 else 'MISSED'}.",
            f"First ok pose after {pose:.1f} s, {after_start:.1f} s after the server started "
            f"(max {after_start_max:.1f} s), from the {by} implementation: the <= "
            f"{FIRST_POSE_GOAL_S:.0f} s goal (from the server's start) is "
            f"{'met' if after_start_max <= FIRST_POSE_GOAL_S else 'MISSED'}.",
            "",
            pace,
        ]
    )


README = ROOT / "README.md"
BEGIN, END = "<!-- first-run:begin -->", "<!-- first-run:end -->"


def write_readme(text: str) -> None:
    """Replace the README's block between the first-run markers with ``text``."""
    readme = README.read_text()
    i, j = readme.find(BEGIN), readme.find(END)
    if i < 0 or j < i:
        raise SystemExit(f"README.md has no {BEGIN} ... {END} block")
    README.write_text(readme[: i + len(BEGIN)] + "\n" + text + "\n" + readme[j:])


if __name__ == "__main__":
    main()
