"""``make bench``: regenerate every table and plot of docs/results.md from scratch, with
fixed seeds, and write the document. The numbers in the file are the ones this run printed.

Run: ``python bench/report.py [--quick]`` (--quick: fewer frames, for trying it out).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench import accuracy, baseline, goals, paper, physics, realistic, robustness  # noqa: E402

DOC = ROOT / "docs" / "results.md"
IMG = ROOT / "docs" / "img" / "results"


def _rel(p: Path) -> str:
    return str(p.relative_to(DOC.parent))


README = ROOT / "README.md"
BEGIN, END = "<!-- bench:begin", "<!-- bench:end -->"


def update_readme(lines: list[str]) -> None:
    """Replace the README's generated block (between its bench markers) with ``lines``."""
    text = README.read_text()
    i, j = text.find(BEGIN), text.find(END)
    if i < 0 or j < i:
        raise SystemExit(f"{README}: the bench markers are missing")
    head = text[: text.index("\n", i) + 1]
    README.write_text(head + "\n".join(lines) + "\n" + text[j:])


def _script(name: str, *args: str) -> str:
    """Run another benchmark script in its own process; return what it printed."""
    out = subprocess.run(
        [sys.executable, str(ROOT / "bench" / name), *args],
        check=True,
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    print(out.stdout, flush=True)
    return out.stdout.strip()


def los_vs_ml(acc_summary) -> list[str]:
    """Where the paper's line-of-sight refinement beats our ML refinement and where not,
    per light level, by median position and attitude error (5 % margin: level)."""
    out = []
    for light in accuracy.LUX:
        ml, los = acc_summary[(light, "full (ML)")], acc_summary[(light, "paper LOS")]
        verdicts = {}
        for idx, what in ((1, "position"), (2, "attitude")):
            wins, loses = [], []
            for r in accuracy.RANGES_M:
                a, b = los[r][idx]["median"], ml[r][idx]["median"]
                if not (np.isfinite(a) and np.isfinite(b)):
                    continue
                if a < 0.95 * b:
                    wins.append(f"{r:g}")
                elif b < 0.95 * a:
                    loses.append(f"{r:g}")
            verdicts[what] = (wins, loses)
        parts = []
        for what, (wins, loses) in verdicts.items():
            s = (
                f"{what}: LOS is better at {', '.join(wins)} m"
                if wins
                else (f"{what}: LOS is better at no range")
            )
            s += f", ML at {', '.join(loses)} m" if loses else ", ML at none"
            parts.append(s)
        out.append(
            f"The paper's LOS refinement vs our ML refinement ({light}, median errors, "
            "5 % margin, else level): " + "; ".join(parts) + "."
        )
    return out


def realistic_findings(real) -> list[str]:
    """The findings the realistic-sensor run gives (``findings``' share of them, and
    what ``--only realistic`` rewrites in the Findings list)."""
    out: list[str] = []
    s = realistic.summarise(real)
    gains = [
        (
            r,
            s[("realistic", r)]["pos"]["median"],
            s[("realistic, calibrated", r)]["pos"]["median"],
            s[("ideal", r)]["pos"]["median"],
        )
        for r in realistic.RANGES_M
    ]
    helped = [g for g in gains if g[2] < 0.5 * g[1]]
    if helped:
        out.append(
            "Range calibration halves the realistic sensor's median position error "
            "or better at "
            + ", ".join(f"{r:g} m ({a:.2f} -> {b:.2f} mm; ideal {c:.2f})" for r, a, b, c in helped)
            + "."
        )
    far = [x for x in real["long"] if x[1] >= 3.0 and x[2]]  # the rule's 3-8 m
    out.append(
        f"Long range (3-8 m, attitudes up to 20 deg): {sum(x[3] for x in far)} "
        f"wrong `ok` poses of {len(far)} over the three sensors with the model's "
        f"covariance, {sum(x[7] for x in far)} with the calibrated one (3 of its "
        "sigmas are a narrower bound)."
    )
    nees: dict[tuple, list[float]] = {}
    nees_cal: dict[tuple, list[float]] = {}
    for x in real["long"]:
        if x[2]:
            nees.setdefault((x[0], x[1]), []).append(x[4])
            nees_cal.setdefault((x[0], x[1]), []).append(x[6])
    spread = [float(np.sqrt(np.mean(v) / 6.0)) for v in nees.values()]
    if spread:
        lo, hi = min(spread), max(spread)
        verdict = (
            "the reported sigmas are wider than the errors at every range and sensor"
            if hi < 0.9
            else "**worse:** the reported sigmas are narrower than the "
            "errors at every range and sensor"
            if lo > 1.1
            else "the reported sigmas are wider than the errors in some cases, narrower "
            "or level in others"
        )
        out.append(
            f"Pose covariance, 0.7-8 m, three sensors: the errors' spread is "
            f"{lo:.2f}-{hi:.2f} x the reported one (sqrt of mean NEES / 6); "
            f"{verdict}."
        )
        cells = [realistic.consistency(np.array(v)) for v in nees_cal.values()]
        inside = sum(c[3] == "in band" for c in cells)
        sc = [float(np.sqrt(c[0] / 6.0)) for c in cells]
        narrow = [
            f"{k[1]:g} m ({k[0]})"
            for k, c in zip(nees_cal, cells, strict=True)
            if c[3] == "too narrow"
        ]
        out.append(
            f"With the covariance calibrated per sensor on other frames "
            f"(`tofpose calibrate-covariance`): mean NEES inside its 95 % band in "
            f"{inside} of {len(cells)} range-sensor cells, errors / reported sigmas "
            f"{min(sc):.2f}-{max(sc):.2f}"
            + (f"; too narrow at {', '.join(narrow)}" if narrow else "")
            + "."
        )
    return out


def findings(acc_summary, rob, base_rows, stab, step_data, real=None) -> list[str]:
    """Plain statements computed from this run, including where we are worse."""
    out = []
    full = acc_summary[("normal (1000 lux)", "full (ML)")]
    oracle = acc_summary[("normal (1000 lux)", "oracle")]
    ok_ranges = [r for r in accuracy.RANGES_M if full[r][0] >= 0.9]
    short = [f"{r:g} m ({100 * full[r][0]:.0f} %)" for r in accuracy.RANGES_M if full[r][0] < 0.9]
    out.append(
        f"The full pipeline gives a pose in >= 90 % of frames from {min(ok_ranges):g} "
        f"m to {max(ok_ranges):g} m at 1000 lux"
        + (f"; less at {', '.join(short)}." if short else ".")
    )
    paper_rows = acc_summary[("normal (1000 lux)", "paper as written")]
    works = [r for r in accuracy.RANGES_M if paper_rows[r][0] >= 0.9]
    fails = [r for r in accuracy.RANGES_M if paper_rows[r][0] == 0.0]
    if works:
        out.append(
            f"The paper's algorithm as written (`PipelineConfig.paper()`) gives a pose "
            f"in >= 90 % of frames from {min(works):g} to {max(works):g} m at 1000 lux"
            + (f" and in none at {', '.join(f'{r:g}' for r in fails)} m" if fails else "")
            + "."
        )
    if real is not None:
        out.extend(realistic_findings(real))
    for light in accuracy.LUX:
        ml, svd = acc_summary[(light, "full (ML)")], acc_summary[(light, "no refinement")]
        ranges = [
            r
            for r in accuracy.RANGES_M
            if np.isfinite(svd[r][1]["median"]) and np.isfinite(ml[r][1]["median"])
        ]
        # "worse" needs a margin: 5 % of a median over 20 frames is within its noise
        worse = [r for r in ranges if svd[r][1]["median"] < 0.95 * ml[r][1]["median"]]
        level = [
            r
            for r in ranges
            if 0.95 * ml[r][1]["median"] <= svd[r][1]["median"] < ml[r][1]["median"]
        ]
        tail = [r for r in ranges if svd[r][1]["p95"] < 0.95 * ml[r][1]["p95"] and r not in worse]
        if worse:
            out.append(
                f"**Worse ({light}):** the median position error without refinement "
                "(weighted SVD only) is lower than with our ML refinement at "
                + ", ".join(f"{r:g}" for r in worse)
                + " m."
            )
        better = [r for r in ranges if ml[r][1]["median"] < svd[r][1]["median"]]
        parts = []
        if level:
            parts.append(
                "ML refinement and weighted SVD alone are level (medians within 5 %) "
                "at " + ", ".join(f"{r:g}" for r in level) + " m"
            )
        if tail:
            parts.append(
                "**worse:** ML's 95th percentile position error is larger than weighted "
                "SVD's at " + ", ".join(f"{r:g}" for r in tail) + " m"
            )
        if len(better) == len(ranges) - len(level) - len(worse):
            parts.append("ML's median error is lower at every other range")
        out.append(f"{light}: " + "; ".join(parts) + ".")
    out += los_vs_ml(acc_summary)
    gaps = [
        full[r][1]["median"] / oracle[r][1]["median"]
        for r in accuracy.RANGES_M
        if np.isfinite(full[r][1]["median"]) and oracle[r][1]["median"] > 0
    ]
    if gaps:
        out.append(
            f"Gap to the oracle (median position error, full / oracle): median "
            f"{np.median(gaps):.1f}x, worst {max(gaps):.1f}x over the range."
        )
    P697, keep697, _ = stab["stability-697"]
    P5712, keep5712, _ = stab["stability-5712"]
    f697 = np.ptp(P697[keep697], axis=0)
    f5712 = np.ptp(P5712[keep5712], axis=0)
    p697 = np.array(paper.PAPER["697-removed"][3])
    p5712 = np.array(paper.PAPER["5712"][3])

    def pairs(ours, theirs) -> str:
        return ", ".join(
            f"{a} {x:.3f}/{y:.3f}" for a, x, y in zip(paper.AXES, ours, theirs, strict=True)
        )

    out.append(
        "Stability (fluctuation range, singular points removed), ours/paper: 697 mm "
        + pairs(f697, p697)
        + "; 5712 mm "
        + pairs(f5712, p5712)
        + "."
    )
    worse_stab = [a for a, x, y in zip(paper.AXES, f5712, p5712, strict=True) if x > y]
    if worse_stab:
        out.append(
            "**Worse:** at 5712 mm our simulated fluctuation exceeds the paper's in "
            + ", ".join(worse_stab)
            + f" (our run: {len(P5712)} frames; the paper "
            "recorded ~6000 s)."
        )
    diffs = [abs(d - t) for _, _, d, t, _, _, _ in step_data]
    out.append(
        f"Attitude steps: |measured - true| change {min(diffs):.3f}-{max(diffs):.3f} deg "
        f"(paper 0.001-0.057 deg; requirement 0.15 deg)."
    )
    ransac10 = rob[("spurious", 10, robustness.METHODS[2])][1]
    conv10 = rob[("spurious", 10, robustness.METHODS[3])]
    da10 = rob[("spurious", 10, robustness.METHODS[0])][1]
    cov4 = {m: rob[("covered", max(robustness.COVERED), m)] for m in robustness.METHODS}
    covered_sentence = (
        f"With {max(robustness.COVERED)} of 8 markers covered: "
        + ", ".join(
            f"{m} {100 * v[0]:.0f} % ok / {100 * v[2]:.0f} % wrong" for m, v in cov4.items()
        )
        + "."
    )
    worst_wrong = max(rob[("spurious", n, robustness.METHODS[0])][2] for n in robustness.SPURIOUS)
    out.append(
        f"With 10 spurious blobs the correct-match rate is {100 * da10:.0f} % for "
        f"annealing + fallback and {100 * ransac10:.0f} % for RANSAC at equal time "
        f"({100 * conv10[1]:.0f} % for RANSAC run to 99 % confidence, which takes "
        f"{conv10[3]:.1f} ms a frame there); "
        + (
            "annealing + fallback never reports a wrong pose (> 1 deg or 20 mm off) "
            "at any number of spurious blobs. "
            if worst_wrong == 0
            else f"annealing + fallback reports a wrong pose (> 1 deg or 20 mm off) in up "
            f"to {100 * worst_wrong:.0f} % of frames. "
        )
        + covered_sentence
    )
    t_ours = np.median([base_rows[r]["tofpose"][3] for r in baseline.RANGES_M])
    t_base = np.median([base_rows[r]["solvePnP"][3] for r in baseline.RANGES_M])
    ratios = [
        base_rows[r]["solvePnP"][1]["median"] / base_rows[r]["tofpose"][1]["median"]
        for r in baseline.RANGES_M
        if np.isfinite(base_rows[r]["solvePnP"][1]["median"])
    ]
    reach = max(
        (r for r in baseline.RANGES_M if base_rows[r]["solvePnP"][0] >= 0.5), default=float("nan")
    )
    out.append(
        f"**Worse:** OpenCV SimpleBlobDetector + solvePnP is {t_ours / t_base:.0f}x "
        f"faster per frame ({t_base:.2f} vs {t_ours:.2f} ms median), even before it "
        f"solves correspondences; its median position error is {min(ratios):.0f}-"
        f"{max(ratios):.0f}x ours and it gives a pose in half the frames or more only "
        f"up to {reach:g} m: it ignores the distance image."
    )
    return out


def _pipeline_verdict(pipe_tab: str) -> str:
    """Sentences on the speed goals (acquisition <= 1 ms, tracking <= 0.3 ms median per
    frame) and the ratio to OpenCV, from the printed totals table (first table)."""
    first = pipe_tab.split("\n\n")[0]  # the totals table, before the per-stage one
    lines = [ln for ln in first.splitlines() if ln.startswith("|")]
    header = [c.strip() for c in lines[0].split("|")[1:-1]]
    rows = [[c.strip() for c in ln.split("|")[1:-1]] for ln in lines if " m |" in ln]

    def col(name: str) -> list[float]:
        i = header.index(name)
        return [float(r[i].split("/")[0]) for r in rows if len(r) == len(header)]

    out = []
    ranges = [r[0] for r in rows if len(r) == len(header)]
    for name, goal in (
        ("acquisition ms", 1.0),
        ("tracking ms", 0.3),
        ("tracking ms, range-corrected", 0.3),
    ):
        v = col(name)
        met = [rg for rg, x in zip(ranges, v, strict=True) if x <= goal]
        verdict = (
            "met"
            if len(met) == len(v)
            else "**not met**"
            if not met
            else f"met at {', '.join(met)} only"
        )
        out.append(
            f"The {goal:g} ms goal for {name.replace(' ms', '')} is {verdict}: medians "
            f"{min(v):.2f}-{max(v):.2f} ms."
        )
    i_c = header.index("ms in compiled code (acq / track)")
    compiled = [float(r[i_c].split("/")[0]) for r in rows if len(r) == len(header)]
    glue = [a - c for a, c in zip(col("acquisition ms"), compiled, strict=True)]
    share = [c / a for a, c in zip(col("acquisition ms"), compiled, strict=True)]
    out.append(
        f"Of an acquisition frame, compiled code (kernels, OpenCV, SciPy) takes "
        f"{min(compiled):.2f}-{max(compiled):.2f} ms ({min(share):.0%}-"
        f"{max(share):.0%}); Python and NumPy the remaining {min(glue):.2f}-"
        f"{max(glue):.2f} ms (the profiled passes and the timed ones are separate runs)."
    )
    ra, rt = col("acquisition / OpenCV"), col("tracking / OpenCV")
    out.append(
        f"Against OpenCV on the same frames: acquisition {min(ra):.1f}-{max(ra):.1f}x, "
        f"tracking {min(rt):.1f}-{max(rt):.1f}x its time."
    )
    return " ".join(out)


DYN_BEGIN, DYN_END = "<!-- dynamics:begin -->", "<!-- dynamics:end -->"


def dynamics_section(quick: bool) -> str:
    """The "Relative state and latency" section from ``bench/dynamics.py``, between its
    markers (``--only dynamics`` regenerates just this block of docs/results.md)."""
    tab = _script("dynamics.py", "--seeds", "1" if quick else "3")
    return "\n".join(
        [
            DYN_BEGIN,
            "## Relative state and latency",
            "",
            '`bench/dynamics.py` (docs/algorithm.md, "Relative state"): the turntable\'s yaw '
            "runs the sine of issue 29's done-when (5 deg, 4 s) with the camera on it, frames "
            "rendered with the sensor's motion artefacts and measured by the server's pipeline; "
            "the filter's rate "
            "error for each motion model (and on a free tumble, measured by the default "
            "pipeline); the latency fit (`tofpose.lab.dynamics`) on poses "
            "stamped "
            "late by a programmed delay; the filter's cost per frame. This section was "
            f"regenerated on {datetime.date.today().isoformat()}.",
            "",
            tab,
            "",
            DYN_END,
        ]
    )


SCALE_BEGIN, SCALE_END = "<!-- scaleout:begin -->", "<!-- scaleout:end -->"


def scaleout_section(quick: bool) -> str:
    """The "Scale-out on Dask" section from ``bench/scaleout.py``, between its markers
    (``--only scaleout`` regenerates just this block)."""
    out = _script("scaleout.py", *(["--quick"] if quick else []))
    return "\n".join(
        [
            SCALE_BEGIN,
            "## Scale-out on Dask",
            "",
            "`bench/scaleout.py` (docs/scaleout.md): `tofpose study` and `tofpose reprocess` on "
            "a LocalCluster of 1 and 2 worker processes of this 2-core machine, against the "
            "same work in one process; numba's cache on the workers; the scheduler's and the "
            "store's cost per task; the server's live loop while a study runs. This section "
            f"was regenerated on {datetime.date.today().isoformat()}.",
            "",
            out,
            "",
            SCALE_END,
        ]
    )


GOALS_BEGIN, GOALS_END = "<!-- goals:begin -->", "<!-- goals:end -->"


def goals_table(quick: bool) -> str:
    """Issue 47's table measured (``bench/goals.py``, in this process: its progress shows
    on stderr), printed and returned as Markdown."""
    before = os.getloadavg()[0]
    rows, offenders = goals.run(quick)
    text = goals.report(rows, offenders, (before, os.getloadavg()[0]))
    print(text, flush=True)
    return text


def goals_section(table_md: str) -> str:
    """The "Where users wait" section of docs/results.md around ``table_md``, between its
    markers (``--only goals`` regenerates just this block, and the README's copy)."""
    return "\n".join(
        [
            GOALS_BEGIN,
            "## Where users wait: issue 47's goals",
            "",
            "`bench/goals.py`: every row of issue 47's table measured in one run on this "
            "machine, each beside a reference measured in the same run (medians over "
            "repeats, min-max in brackets; ratio = median measured / median reference; "
            '"met" is computed from these numbers). The first pose is counted from '
            "`tofpose serve`'s start as `make run` starts it, with an empty numba cache (the "
            "venv and the dashboard's build, which a fresh clone's `make run` does first, "
            "are not counted: `bench/first_run.py` times those). This section was "
            f"regenerated on {datetime.date.today().isoformat()}.",
            "",
            table_md,
            "",
            GOALS_END,
        ]
    )


def readme_goals(table_md: str) -> list[str]:
    """The README's copy of the goals table, between the goals markers (inside its
    generated block)."""
    return [
        GOALS_BEGIN,
        "`python bench/goals.py`: issue 47's goals, each beside a reference measured in "
        "the same run (details in [docs/results.md](docs/results.md)):",
        "",
        table_md,
        GOALS_END,
    ]


def update_readme_goals(table_md: str) -> None:
    """Replace the README's goals block (inserted at the end of its generated block when
    it has none yet)."""
    text = README.read_text()
    block = "\n".join(readme_goals(table_md))
    i, j = text.find(GOALS_BEGIN), text.find(GOALS_END)
    if i >= 0 and j > i:
        text = text[:i] + block + text[j + len(GOALS_END) :]
    else:
        k = text.find(END)
        if k < 0:
            raise SystemExit(f"{README}: the bench markers are missing")
        text = text[:k] + "\n" + block + "\n" + text[k:]
    README.write_text(text)


SAFETY_BEGIN, SAFETY_END = "<!-- safety:begin -->", "<!-- safety:end -->"
PIXEL_BEGIN, PIXEL_END = "<!-- pixelfit:begin -->", "<!-- pixelfit:end -->"


def pixelfit_section(quick: bool) -> str:
    """ "Pixel-level fit against the bound" from ``bench/pixelfit.py``, between its markers
    (``--only pixelfit`` regenerates just this block)."""
    out = _script(
        "pixelfit.py",
        "--frames",
        "6" if quick else "12",
        "--repeats",
        "1" if quick else "2",
        "--supersampling",
        "64",
        "--product",
    )
    return "\n".join(
        [
            PIXEL_BEGIN,
            "## Pixel-level fit against the bound",
            "",
            "`bench/pixelfit.py` (`tofpose.stages.pixelfit`, docs/algorithm.md): the pose "
            "refined on the matched markers' raw gray and distance pixels (a forward model of "
            "each disc's pixel-integrated image) beside the centroid pipeline it starts from, "
            "both as RMS error over the Cramer-Rao bound of the same frames (`bench/crlb.py`), "
            "and the fit's errors over its own sigmas (1 = its inverse-Fisher covariance is "
            "right). Frames rendered with 64 x 64 sampling of rim pixels (a coarser renderer "
            "is itself a model error: up to a bound or two at 16 x 16, a quarter of one at "
            "32 x 32 at 2 m). The second table is the fit as the product runs it, with the "
            "camera configured as a user would; a common range offset, fitted where the "
            "camera is not declared bias-free, costs position beyond the offset-known bound. "
            "The discs' images and their analytic "
            "pose derivatives are compiled kernels; its ms per frame are the cost to bring "
            "down before it runs in the live loop. This "
            f"section was regenerated on {datetime.date.today().isoformat()}.",
            "",
            out,
            "",
            PIXEL_END,
        ]
    )


LIVEFIT_BEGIN, LIVEFIT_END = "<!-- livefit:begin -->", "<!-- livefit:end -->"


def livefit_section(quick: bool) -> str:
    """ "The pixel fit in the live loop" from ``bench/live_pixel_fit.py``, between its
    markers (``--only livefit`` regenerates just this block)."""
    out = _script(
        "live_pixel_fit.py",
        "--seconds",
        "4" if quick else "8",
        "--repeats",
        "1" if quick else "2",
    )
    return "\n".join(
        [
            LIVEFIT_BEGIN,
            "### The pixel fit in the live loop",
            "",
            "`bench/live_pixel_fit.py`: the server (`tofpose serve`, simulated lab) with "
            "`TOFPOSE_PIXEL_FIT` off and on, the target at each range: ok poses a second "
            "on the live WebSocket, the latency from the frame reaching the server to a "
            "client, the share of ok poses the fit refined, its time, and the sigmas the "
            "poses were reported with. The fit runs on the acquisition thread; a loop "
            "slower than the camera measures the newest frame each time. This section was "
            f"regenerated on {datetime.date.today().isoformat()}.",
            "",
            out,
            "",
            LIVEFIT_END,
        ]
    )


def safety_section(quick: bool) -> str:
    """The "STOP under load" section from ``bench/stop_latency.py``, between its markers
    (``--only safety`` regenerates just this block)."""
    out = _script(
        "stop_latency.py",
        "--clients",
        "0",
        "100",
        "--readers",
        "0",
        "--stops",
        "20" if quick else "40",
        "--exports",
        "60",
    )
    return "\n".join(
        [
            SAFETY_BEGIN,
            "## STOP under load, refused studies",
            "",
            '`bench/stop_latency.py` (docs/server.md, "Threat model"): `POST /api/motion/stop` '
            "timed on a fresh `tofpose serve` with 0 and 100 `/ws/live` clients that never read "
            "(the caps raised so that all are served), then while 60 clients download a "
            "campaign's PDF report and MCAP at once (the server's report workers serve 2 at a "
            "time and queue 8; the rest are refused with 503 at once), then the cost of "
            "refusing a 1.8 M-cell study spec. The goal: STOP's median under 50 ms in every "
            f"row. This section was regenerated on {datetime.date.today().isoformat()}.",
            "",
            out,
            "",
            SAFETY_END,
        ]
    )


def replace_section(begin: str, end: str, section: str) -> None:
    """Put ``section`` in place of docs/results.md's block between ``begin`` and ``end``
    (before "## Speed" when the document has none yet)."""
    text = DOC.read_text()
    i, j = text.find(begin), text.find(end)
    if i >= 0 and j > i:
        text = text[:i] + section + text[j + len(end) :]
    else:
        k = text.index("## Speed")
        text = text[:k] + section + "\n\n" + text[k:]
    DOC.write_text(text)


def replace_heading_block(heading: str, section: str) -> None:
    """Put ``section`` in place of docs/results.md's block from the line ``heading`` to
    the next "## " heading or the next section marker ("<!-- name:begin -->" of a block
    that ``replace_section`` owns), whichever comes first (the marker stays), or to the
    end of the document."""
    text = DOC.read_text()
    i = text.index(heading + "\n")
    ends = [text.find(m, i + len(heading)) for m in ("\n## ", "\n<!-- ")]
    j = min([k for k in ends if k >= 0], default=len(text))
    DOC.write_text(text[:i] + section.rstrip("\n") + "\n" + text[j:])


def accuracy_section(quick: bool) -> str:
    """ "Accuracy over the operating range" (``--only accuracy`` regenerates just this
    block, with its plot)."""
    n_acc = 4 if quick else 20
    acc_summary = accuracy.summarise(accuracy.run(n_acc))
    IMG.mkdir(parents=True, exist_ok=True)
    accuracy.plot(acc_summary, IMG / "accuracy-range.png")
    return accuracy.markdown(acc_summary, _rel(IMG / "accuracy-range.png"), n_acc)


def physics_section(quick: bool) -> str:
    """ "Physics robustness study" (``--only physics`` regenerates just this block, with
    its plots)."""
    n_phys = 4 if quick else 24
    phys = physics.run(n_phys)
    IMG.mkdir(parents=True, exist_ok=True)
    physics.plot(phys, IMG / "physics.png")
    compared = physics.compare_pixel_fit(n_phys // 2 if not quick else n_phys)
    wrapped = physics.beyond_unambiguous(n_phys)
    return "\n".join(
        [
            physics.markdown(phys, _rel(IMG / "physics.png"), n_phys),
            physics.pixel_fit_markdown(compared, n_phys // 2 if not quick else n_phys),
            physics.beyond_unambiguous_markdown(wrapped, n_phys),
        ]
    )


#: how the Findings that ``realistic_findings`` writes begin (``--only realistic``
#: replaces the ones that do)
REALISTIC_FINDING_STARTS = (
    "Range calibration ",
    "Long range (3-8 m",
    "Pose covariance, 0.7-8 m",
    "With the covariance calibrated",
)


def realistic_section(quick: bool) -> tuple[str, list[str]]:
    """ "Realistic sensor and range calibration" and its findings (``--only realistic``
    regenerates both, with the plot)."""
    n_real, n_long, n_cal = (4, 20, 30) if quick else (16, 90, 150)
    real = realistic.run(n_real, long_frames=n_long, cal_frames=n_cal)
    IMG.mkdir(parents=True, exist_ok=True)
    realistic.plot(real, IMG / "realistic.png")
    return realistic.markdown(real, _rel(IMG / "realistic.png"), n_real), realistic_findings(real)


def replace_findings(starts: tuple[str, ...], found: list[str]) -> None:
    """In docs/results.md's Findings list, the bullets that begin with one of ``starts``
    replaced by ``found``, where the first of them stood."""
    text = DOC.read_text()
    i = text.index("## Findings\n")
    j = text.index("\n## ", i + 1)
    lines = text[i:j].split("\n")
    old = [k for k, line in enumerate(lines) if line.startswith(tuple(f"- {s}" for s in starts))]
    at = old[0] if old else len(lines)
    kept = [line for k, line in enumerate(lines) if k not in old]
    new = kept[:at] + [f"- {s}" for s in found] + kept[at:]
    DOC.write_text(text[:i] + "\n".join(new) + text[j:])


def foreign_section(recordings: list[str]) -> str:
    """ "Frames from another renderer": ``bench/foreign.py`` on ``recordings`` (``--only
    foreign --foreign REC.h5 ...`` regenerates just this block)."""
    return "\n".join(
        [
            "## Frames from another renderer",
            "",
            "`bench/foreign.py` on recordings made by a ToF renderer that shares no code "
            "with `tofpose.sim` (area-integrated pixels, cos^4 fall-off, a dark but not black "
            "plate mixing into partly covered pixels, no wall; per file: far poses, "
            "uncalibrated systematic range errors, reflectors saturating a fixed exposure, "
            "marker-like specular glints). They are not shipped with the project; the oracle "
            "rows give the pipeline the true correspondences. Each recording as `tofpose "
            "estimate` measures it by default: the range bias learned over the recording "
            "first, each pose refined on its markers' pixels (the pixel-level fit; the "
            "centroid pose where the fit falls back).",
            "",
            _script("foreign.py", *recordings, "--quiet"),
            "",
            "The same recordings with the centroid pose only (`tofpose estimate "
            "--no-pixel-fit`: no pixel-level fit after the pipeline, and the configured "
            "range-offset prior, which is learned only with the pixel fit; "
            "docs/algorithm.md).",
            "",
            _script("foreign.py", *recordings, "--quiet", "--no-oracle", "--no-pixel-fit"),
            "",
        ]
    )


def replace_dynamics(section: str) -> None:
    replace_section(DYN_BEGIN, DYN_END, section)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument(
        "--only",
        choices=[
            "accuracy",
            "pixelfit",
            "livefit",
            "dynamics",
            "scaleout",
            "safety",
            "foreign",
            "physics",
            "realistic",
            "goals",
        ],
        help="regenerate one section of docs/results.md in place",
    )
    ap.add_argument(
        "--foreign",
        nargs="*",
        default=[],
        metavar="REC.h5",
        help="recordings from a renderer other than tofpose.sim (with truth) to "
        "judge the pipeline on (bench/foreign.py); none are shipped",
    )
    args = ap.parse_args()
    q = args.quick
    if args.only == "accuracy":
        replace_heading_block("## Accuracy over the operating range", accuracy_section(q))
        print(f"rewrote the accuracy section of {DOC}", file=sys.stderr)
        return
    if args.only == "physics":
        replace_heading_block("## Physics robustness study", physics_section(q))
        print(f"rewrote the physics section of {DOC}", file=sys.stderr)
        return
    if args.only == "realistic":
        section, found = realistic_section(q)
        replace_heading_block("## Realistic sensor and range calibration", section)
        replace_findings(REALISTIC_FINDING_STARTS, found)
        print(f"rewrote the realistic-sensor section and its findings of {DOC}", file=sys.stderr)
        return
    if args.only == "pixelfit":
        replace_section(PIXEL_BEGIN, PIXEL_END, pixelfit_section(q))
        print(f"rewrote the pixel fit section of {DOC}", file=sys.stderr)
        return
    if args.only == "livefit":
        replace_section(LIVEFIT_BEGIN, LIVEFIT_END, livefit_section(q))
        print(f"rewrote the live pixel fit section of {DOC}", file=sys.stderr)
        return
    if args.only == "dynamics":
        replace_dynamics(dynamics_section(q))
        print(f"rewrote the dynamics section of {DOC}", file=sys.stderr)
        return
    if args.only == "scaleout":
        replace_section(SCALE_BEGIN, SCALE_END, scaleout_section(q))
        print(f"rewrote the scale-out section of {DOC}", file=sys.stderr)
        return
    if args.only == "foreign":
        if not args.foreign:
            ap.error("--only foreign needs the recordings: --foreign REC.h5 [REC.h5 ...]")
        replace_heading_block("## Frames from another renderer", foreign_section(args.foreign))
        print(f"rewrote the foreign-renderer section of {DOC}", file=sys.stderr)
        return
    if args.only == "goals":
        table_md = goals_table(q)
        replace_section(GOALS_BEGIN, GOALS_END, goals_section(table_md))
        update_readme_goals(table_md)
        print(f"rewrote the goals section of {DOC} and its table in {README}", file=sys.stderr)
        return
    if args.only == "safety":
        replace_section(SAFETY_BEGIN, SAFETY_END, safety_section(q))
        print(f"rewrote the safety section of {DOC}", file=sys.stderr)
        return
    IMG.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()

    stab, step_data, range_data, pimgs = paper.run(IMG, 120 if q else 900, 15 if q else 30)
    sec_paper = paper.markdown(
        stab, step_data, range_data, [_rel(p) for p in pimgs], 120 if q else 900
    )
    print(sec_paper, flush=True)

    n_acc = 4 if q else 20
    acc_summary = accuracy.summarise(accuracy.run(n_acc))
    accuracy.plot(acc_summary, IMG / "accuracy-range.png")
    sec_acc = accuracy.markdown(acc_summary, _rel(IMG / "accuracy-range.png"), n_acc)
    print(sec_acc, flush=True)

    n_rob = 5 if q else 24
    rob = robustness.run(n_rob)
    robustness.plot(rob, IMG / "robustness.png")
    sec_rob = robustness.markdown(rob, _rel(IMG / "robustness.png"), n_rob)
    print(sec_rob, flush=True)

    n_phys = 4 if q else 24
    phys = physics.run(n_phys)
    physics.plot(phys, IMG / "physics.png")
    sec_phys = physics.markdown(phys, _rel(IMG / "physics.png"), n_phys)
    print(sec_phys, flush=True)

    sec_foreign = foreign_section(args.foreign) if args.foreign else ""

    n_real, n_long, n_cal = (4, 20, 30) if q else (16, 90, 150)
    real = realistic.run(n_real, long_frames=n_long, cal_frames=n_cal)
    realistic.plot(real, IMG / "realistic.png")
    sec_real = realistic.markdown(real, _rel(IMG / "realistic.png"), n_real)
    print(sec_real, flush=True)

    n_base = 4 if q else 16
    base_rows = baseline.run(n_base)
    baseline.plot(base_rows, IMG / "baseline.png")
    sec_base = baseline.markdown(base_rows, _rel(IMG / "baseline.png"), n_base)
    print(sec_base, flush=True)

    pipe_tab = _script("pipeline.py", "--frames", "20" if q else "60")
    sim_tab = _script("sim.py", "--frames", "10" if q else "40")
    startup_tab = _script("startup.py", "--repeats", "3" if q else "10")
    live_tab = _script(
        "live.py",
        "--clients",
        "1",
        "10",
        "50",
        "--rates",
        "10",
        "30",
        "--seconds",
        "2" if q else "4",
        "--repeats",
        "1" if q else "2",
        "--dashboards",
        "1",
        "5",
    )
    dev_tab = _script("devices.py", "--repeats", "2" if q else "5")
    interop_tab = _script(
        "interop.py",
        "--frames",
        *(("200", "400") if q else ("1000", "10000")),
        "--repeats",
        "1" if q else "3",
        "--seconds",
        "2" if q else "5",
        "--screenshot",
        str(ROOT / "docs" / "img" / "interop" / "rerun.png"),
    )

    minutes = (time.monotonic() - t0) / 60.0
    head = [
        "# Results",
        "",
        f"Generated by `make bench` (`python bench/report.py`) on "
        f"{datetime.date.today().isoformat()}, {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}, in {minutes:.1f} min. Every number below is "
        "what that run printed; seeds are fixed. All frames come from the simulator "
        "(`tofpose.sim`)"
        + (', except those of "Frames from another renderer"' if args.foreign else "")
        + "; there is no real camera data in this document.",
        "",
        "## Findings",
        "",
        *[f"- {s}" for s in findings(acc_summary, rob, base_rows, stab, step_data, real)],
        "",
    ]
    speed = [
        "## Speed",
        "",
        "Pipeline, ms per frame on one core (`bench/pipeline.py`): acquisition and "
        "tracking, with OpenCV timed on the same frames in the same run; then "
        "acquisition per stage:",
        "",
        pipe_tab,
        "",
        _pipeline_verdict(pipe_tab),
        "",
        "Simulator (`bench/sim.py`):",
        "",
        sim_tab,
        "",
        "Start-up, each in a fresh process (`bench/startup.py`): the command line, the "
        "library, the pipeline with its kernels from numba's cache, and a first pose; "
        "and which heavy packages each loaded:",
        "",
        startup_tab,
        "",
        "Live server end to end (`bench/live.py`): simulated camera in the server "
        "process, N WebSocket clients in another process on the same 2 cores; latency "
        "from the frame reaching the server to client receipt; then whole dashboards in "
        "Debian's chromium (software rendering, no GPU) sharing the same 2 cores with "
        "the server: frames each page actually drew per second, and the server's CPU:",
        "",
        live_tab,
        "",
        "## Real-device drivers: link loss and recovery",
        "",
        "The server with the `tofcam660` camera and `scpi` rate-table drivers against "
        "the shipped emulators (`bench/devices.py`, default time-outs and back-offs, "
        "docs/devices.md): how long until the device shows degraded, and how long "
        "until it works again (a new pose; motion state ok):",
        "",
        dev_tab,
        "",
        "## Interop: MCAP files and the live Foxglove server",
        "",
        "`bench/interop.py` (docs/interop.md): `tofpose export mcap` / `import mcap` "
        "speed and file size on a simulated recording, the export's peak memory in a "
        "fresh process for two recording lengths, then the live server at 30 Hz: the "
        "pose rate its own WebSocket delivers with the Foxglove server off, idle, "
        "serving a client that reads every channel, one that reads 4 messages a second "
        "(its backlog drops the oldest: the age of what it reads), and one that "
        "subscribes to every channel and never reads:",
        "",
        interop_tab,
        "",
    ]
    sec_dyn = dynamics_section(q)
    sec_scale = scaleout_section(q)
    sec_safety = safety_section(q)
    sec_pixel = pixelfit_section(q)
    sec_livefit = livefit_section(q)
    goals_md = goals_table(q)
    sec_goals = goals_section(goals_md)
    text = "\n".join(
        head
        + [
            sec_paper,
            sec_acc,
            sec_pixel,
            sec_livefit,
            sec_real,
            sec_phys,
            sec_foreign,
            sec_rob,
            sec_base,
            sec_dyn,
            sec_scale,
            sec_safety,
            sec_goals,
        ]
        + speed
    )
    DOC.write_text(text + "\n")
    update_readme(
        [
            f"Generated by `make bench` on {datetime.date.today().isoformat()} "
            f"({platform.processor() or platform.machine()}, Python {platform.python_version()}); "
            "the accuracy, robustness and baseline evidence is in "
            "[docs/results.md](docs/results.md).",
            "",
            "`python bench/pipeline.py`: pipeline time, ms per frame on one core, median / p95, "
            "acquisition and tracking beside OpenCV on the same frames, then per stage:",
            "",
            pipe_tab,
            "",
            _pipeline_verdict(pipe_tab),
            "",
            "`python bench/sim.py`: rendering one simulated frame pair:",
            "",
            sim_tab,
            "",
            "`python bench/live.py`: the live server with N WebSocket clients, then whole "
            "dashboards in chromium, on the same 2 cores:",
            "",
            live_tab,
            "",
            "`python bench/devices.py`: the real-device drivers against the emulators, link "
            "loss and recovery:",
            "",
            dev_tab,
            "",
            *readme_goals(goals_md),
        ]
    )
    print(f"wrote {DOC} in {minutes:.1f} min", file=sys.stderr)


if __name__ == "__main__":
    main()
