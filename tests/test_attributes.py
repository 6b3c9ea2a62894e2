"""The geometric attribute measurements agree with the corpus's own drawn parameters."""

from __future__ import annotations

import pytest

from dbtool.prior.corpora.corpus import make_shape
from dbtool.prior.corpora.words import LOW
from dbtool.robotize.attributes import MEASURES, legs

CASES = [("disk", "thickness"), ("cylinder", "height"), ("egg", "length"), ("plate", "width"),
         ("bar", "roundness"), ("finger", "taper"), ("worm", "curve"), ("ring", "thickness")]


@pytest.mark.parametrize(("family", "attr"), CASES)
def test_the_high_word_measures_higher_than_the_low_word(family, attr):
    shapes = [make_shape(family, i, "reference", 0, 1024) for i in range(12)]
    # an attribute without a low word ("tapered") is compared with the shapes drawn low
    lo = [MEASURES[attr](s.points) for s in shapes if s.description.words().get(attr) == "low"
          or (attr == "taper" and s.description.grades[attr] < LOW)]
    hi = [MEASURES[attr](s.points) for s in shapes if s.description.words().get(attr) == "high"]
    assert lo and hi, "the draw has both ends"
    right = sum(a < b for a in lo for b in hi) / (len(lo) * len(hi))
    assert right >= 0.85, right


def test_legs_are_counted_on_the_ground():
    shapes = [make_shape(f, i, "reference", 0, 1024) for f in ("legged_ball", "legged_disk")
              for i in range(6)]
    right = sum(legs(s.points) == s.description.counts["legs"] for s in shapes)
    assert right >= 10, right
    assert legs(make_shape("block", 0, "reference", 0, 1024).points) == 1


def test_attribute_control_runs_on_a_prior():
    from dbtool.prior.sampling.pipeline import Prior
    from dbtool.robotize.attributes import attribute_control, attribute_prompts, legs_control

    rows = attribute_prompts(["disk", "finger", "legged_ball"])
    assert {"family": "disk", "attribute": "thickness", "low": "a thin disk",
            "high": "a thick disk"} in rows
    assert any(r["low"] == "a finger with three segments" for r in rows)  # no low word: plain
    assert all("legs" in r["low"] for r in rows if r["family"] == "legged_ball")
    prior = Prior.load(with_upsampler=False)
    res = attribute_control(prior, rows[:1], n=2, steps=8)
    assert res[0]["pairs"] == 2 and 0 <= res[0]["right"] <= 2
    assert len(res[0]["low_values"]) == 2 and all(v > 0 for v in res[0]["high_values"])
    leg = legs_control(prior, bodies=("ball",), counts=(4,), n=2, steps=8)
    assert leg[0]["prompt"] == "a ball with four legs" and len(leg[0]["found"]) == 2
