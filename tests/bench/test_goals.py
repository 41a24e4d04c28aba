"""Issue 47's goals table (``bench/goals.py``): a quick run of the cheap rows gives a
table whose every ratio is the run's median measured over its median reference, and
whose verdicts follow from those numbers; ``bench/report.py --only goals`` keeps one
copy of the table in the README's generated block."""

from __future__ import annotations

import re
import statistics

import pytest

from bench import goals, report


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def test_a_quick_run_gives_each_ratio_as_measured_over_reference_of_that_run():
    rows, offenders = goals.run(True, ("startup", "pipeline"))
    keys = [r.key for r in rows]
    assert keys == [
        "help",
        "import",
        "acquisition",
        "tracking",
        "acquisition_calls",
        "tracking_calls",
    ]
    for r in rows:
        assert r.measured and all(v > 0 for v in r.measured)
        if r.reference:
            expected = statistics.median(r.measured) / statistics.median(r.reference)
            assert r.ratio == pytest.approx(expected, rel=1e-12)
    # acquisition and tracking are timed against OpenCV on the same frames: one
    # reference for both
    by = {r.key: r for r in rows}
    assert by["acquisition"].reference == by["tracking"].reference
    # the printed table: header, rule, one line per row; its ratio and verdict cells are
    # those of the numbers
    lines = goals.markdown(rows).splitlines()
    assert _cells(lines[0]) == goals.HEADER
    assert len(lines) == 2 + len(rows)
    for r, line in zip(rows, lines[2:], strict=True):
        what, measured, ref, ratio, goal, met = _cells(line)
        assert what == r.what and goal == r.goal
        assert measured.startswith(f"{statistics.median(r.measured):.{goals._digits(r.measured)}f}")
        if r.reference:
            assert ratio == f"{r.ratio:.2f}x"
            assert ref.startswith(r.reference_what)
        else:
            assert ratio == "-" and ref == "-"
        assert met == ("yes" if r.met else "no")
        if r.kind == "ratio <=":
            assert r.met == (r.ratio <= r.bound)
    # the import row's verdict is what the fresh process loaded
    assert by["import"].met == by["import"].note.endswith("none of them")
    # -X importtime names packages with their ms, the costliest first
    assert offenders and [ms for _, ms in offenders] == sorted(
        (ms for _, ms in offenders), reverse=True
    )
    assert "tofpose" in dict(offenders)


def test_verdicts_follow_the_goal_kind():
    def row(kind, bound, measured, reference, checks=None):
        return goals.Row("k", "w", "s", measured, "r", reference, "g", kind, bound, checks or {})

    assert row("ratio <=", 1.0, [1.0, 3.0, 2.0], [2.0, 2.0, 4.0]).ratio == 1.0
    assert row("ratio <=", 1.0, [1.0, 3.0, 2.0], [2.0, 2.0, 4.0]).met
    assert not row("ratio <=", 0.9, [1.0, 3.0, 2.0], [2.0, 2.0, 4.0]).met
    assert row("ratio >=", 0.9, [9.5], [10.0]).met
    assert not row("ratio >=", 0.9, [9.5], [10.0], {"no chunk run twice": False}).met
    assert row("measured <=", 30.0, [29.0, 31.0, 12.0], [5.0]).met  # median 29
    assert not row("checks", float("nan"), [591.0], [], {"one compiled call": False}).met
    with pytest.raises(ValueError, match="unknown goal kind"):
        _ = row("about", 1.0, [1.0], [1.0]).met
    with pytest.raises(ValueError, match="unknown goal groups"):
        goals.run(True, ("speed",))


def test_only_goals_keeps_one_table_in_the_readmes_generated_block(tmp_path, monkeypatch):
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{report.BEGIN} (generated) -->\nspeed table\n{report.END}\nafter\n")
    monkeypatch.setattr(report, "README", readme)
    report.update_readme_goals("| a |\n|---|\n| 1 |")
    report.update_readme_goals("| a |\n|---|\n| 2 |")
    text = readme.read_text()
    assert text.count(report.GOALS_BEGIN) == 1 and text.count(report.GOALS_END) == 1
    assert "| 2 |" in text and "| 1 |" not in text
    # inside the generated block, after what was there
    assert re.search(
        "speed table\n.*" + re.escape(report.GOALS_END) + "\n" + re.escape(report.END),
        text,
        re.S,
    )
    assert text.endswith("after\n")
