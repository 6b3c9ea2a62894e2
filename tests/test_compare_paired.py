"""Paired differences of the comparison: per-seed pairing, the t interval, the verdicts."""

import math

import pytest

from dbtool.compare.paired import paired_differences, paired_markdown, verdict


def _rows(table: dict[tuple[str, str], list[float]], failed=()) -> list[dict]:
    rows = [{"method": m, "task": t, "seed": s, "status": "done", "metric": v}
            for (m, t), vals in table.items() for s, v in enumerate(vals)]
    for m, t, s in failed:
        rows.append({"method": m, "task": t, "seed": s, "status": "failed", "metric": "nan"})
    return rows


def test_differences_pair_seeds_and_give_a_student_t_interval():
    rows = _rows({("diffusebot", "crawling"): [3.0, 5.0, 4.0],
                  ("prior", "crawling"): [1.0, 2.0, 3.0],  # differences 2, 3, 1
                  ("particle", "crawling"): [9.0, 9.5, 8.0]})  # differences -6, -4.5, -4
    d = {x["other"]: x for x in paired_differences(rows)}
    p = d["prior"]
    assert p["differences"] == [2.0, 3.0, 1.0] and p["n"] == 3 and p["mean"] == 2.0
    assert p["sd"] == pytest.approx(1.0)
    half = 4.302652729911275 / math.sqrt(3)  # t(0.975, 2) * sd / sqrt(n)
    assert (p["lo"], p["hi"]) == (pytest.approx(2 - half), pytest.approx(2 + half))
    assert p["sign"] == 0  # [-0.48, 4.48] holds 0
    assert d["particle"]["sign"] == -1  # [-7.2, -2.5]: below 0
    assert "worse than particle" in verdict(paired_differences(rows), "crawling")
    assert "not separable from prior samples" in verdict(paired_differences(rows), "crawling")


def test_only_seeds_done_by_both_are_paired_and_one_seed_has_no_interval():
    rows = _rows({("diffusebot", "box"): [2.0, 2.0, 2.1], ("cppn", "box"): [1.0]},
                 failed=[("cppn", "box", 1)])
    (d,) = paired_differences(rows)
    assert d["seeds"] == [0] and d["lo"] is None and d["sign"] == 0
    assert verdict([d], "box").endswith(
        "one seed only with diff-CPPN (no interval) (1 paired seed).")
    rows = _rows({("diffusebot", "box"): [2.0, 2.2, 2.1], ("cppn", "box"): [1.0, 1.1, 1.0]})
    assert verdict(paired_differences(rows), "box") == (
        "Moving a box: DiffuseBot is better than every method it was paired with (diff-CPPN; "
        "every 95% interval above 0, 3 paired seeds).")
    text = paired_markdown(rows)
    assert "| Moving a box | diff-CPPN | 3 | 1.07 |" in text and "better" in text
