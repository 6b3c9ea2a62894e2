"""Tip-distance logs of the tendon protocol (docs/realgap.md): reading, checking, writing."""

from __future__ import annotations

import numpy as np
import pytest

from dbtool.realgap.log import (
    HEADER,
    Curve,
    LogError,
    TipLog,
    check_design,
    parse_log,
    read_log,
    write_log,
)

H = ",".join(HEADER)
GOOD = f"""# design: gripper-a
# design_sha: 0123456789abcdef
# source: real
# date: 2025-01-31
{H}
flexion,pull,0,0,40.0
flexion,pull,1,2.5,35.5
flexion,pull,2,5,30.25
flexion,release,3,2.5,33.0
flexion,release,4,0,39.5
extension,pull,0,0,40.0
extension,pull,1,3,46.0
extension,release,2,0,41.0
"""


def write(tmp_path, text: str, name: str = "log.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_reads_a_good_log(tmp_path):
    log = read_log(write(tmp_path, GOOD))
    assert list(log.curves) == ["flexion", "extension"]
    flex = log.curves["flexion"]
    assert flex.phase == ["pull"] * 3 + ["release"] * 2
    np.testing.assert_array_equal(flex.steps, np.arange(5))
    np.testing.assert_array_equal(flex.displacement, [0, 2.5, 5, 2.5, 0])
    np.testing.assert_array_equal(flex.tip, [40, 35.5, 30.25, 33, 39.5])
    d, y = flex.branch("release")
    np.testing.assert_array_equal(d, [2.5, 0])
    np.testing.assert_array_equal(y, [33, 39.5])
    assert log.meta == {"design": "gripper-a", "design_sha": "0123456789abcdef",
                        "source": "real", "date": "2025-01-31"}
    assert log.warnings == []
    assert log.schedule() == {
        "flexion": [("pull", 0.0), ("pull", 2.5), ("pull", 5.0), ("release", 2.5),
                    ("release", 0.0)],
        "extension": [("pull", 0.0), ("pull", 3.0), ("release", 0.0)],
    }


def test_tolerates_bom_crlf_blank_lines_and_whitespace(tmp_path):
    text = "\ufeff" + GOOD.replace(",", " , ").replace("# source: real", "\n  # source:  real ")
    path = tmp_path / "log.csv"
    path.write_bytes(text.replace("\n", "\r\n").encode("utf-8") + b"\r\n\r\n")
    log = read_log(path)
    ref = parse_log(GOOD)
    assert log.meta == ref.meta
    for t, c in ref.curves.items():
        assert log.curves[t].phase == c.phase
        np.testing.assert_array_equal(log.curves[t].displacement, c.displacement)
        np.testing.assert_array_equal(log.curves[t].tip, c.tip)


def test_only_flexion_and_interleaved_tendons():
    only = parse_log(f"# source: sim\n{H}\nflexion,pull,0,0,40\nflexion,pull,1,1,39\n")
    assert list(only.curves) == ["flexion"] and only.source == "sim"
    mixed = parse_log(f"# source: sim\n{H}\nflexion,pull,0,0,40\nextension,pull,0,0,40\n"
                      "flexion,pull,1,1,39\nextension,release,1,0,40\n")
    assert mixed.curves["flexion"].phase == ["pull", "pull"]
    assert mixed.curves["extension"].phase == ["pull", "release"]


def test_comments_without_key_are_notes_and_no_source_warns():
    log = parse_log(f"# a free remark, no colon\n#\n# notes: cold room\n# k_scale: 1.5\n"
                    f"{H}\n# calibrated at 10 30\nflexion,pull,0,0,40\n", name="x.csv")
    assert log.meta == {"notes": "a free remark, no colon; cold room; calibrated at 10 30",
                        "k_scale": "1.5"}
    assert list(log.meta) == ["notes", "k_scale"]
    assert log.warnings == ["x.csv: no source: metadata; assuming real"]
    assert log.source == "real"


def test_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    pull = np.cumsum(rng.uniform(0, 1e-3, 7) * np.pi)
    rel = pull[::-1][1:]
    curve = Curve("flexion", ["pull"] * 7 + ["release"] * 6, np.r_[pull, rel],
                  rng.uniform(1e-9, 80, 13))
    ext = Curve.from_rows("extension", [("pull", 0.0, 1 / 3), ("release", 0.0, 2 / 3)])
    log = TipLog({"extension": ext, "flexion": curve},
                 {"design": "g", "source": "sim", "notes": "a; b", "dt": "1e-4"})
    path = write_log(tmp_path / "sub" / "out.csv", log)
    text = path.read_text()
    assert text.splitlines()[:5] == ["# design: g", "# source: sim", "# notes: a; b",
                                     "# dt: 1e-4", H]
    assert text.splitlines()[5].startswith("flexion,pull,0,")  # flexion first
    back = read_log(path)
    assert back.meta == log.meta and list(back.meta) == list(log.meta)
    assert list(back.curves) == ["flexion", "extension"]
    for t in ("flexion", "extension"):
        assert back.curves[t].phase == log.curves[t].phase
        np.testing.assert_array_equal(back.curves[t].displacement, log.curves[t].displacement)
        np.testing.assert_array_equal(back.curves[t].tip, log.curves[t].tip)
    assert back.schedule() == log.schedule()
    assert not list(path.parent.glob(".*"))  # no temp file left behind


def test_write_refuses_an_invalid_log(tmp_path):
    bad = TipLog({"flexion": Curve.from_rows("flexion", [("pull", 0.0, -1.0)])})
    with pytest.raises(LogError, match="tip_distance_mm must be > 0"):
        write_log(tmp_path / "bad.csv", bad)
    assert not (tmp_path / "bad.csv").exists()
    with pytest.raises(ValueError, match="cannot be written"):
        TipLog({}, {"notes": "two\nlines"}).to_text()


def test_missing_file(tmp_path):
    path = tmp_path / "nope.csv"
    with pytest.raises(LogError) as e:
        read_log(path)
    assert str(e.value) == f"{path}:0: not found"


ROW = "flexion,pull,0,0,40"
BAD = {
    "empty": ("", 1, "no header line"),
    "only comments": ("# source: real\n# design: g\n", 2, "no header line"),
    "missing column": ("tendon,phase,step,tip_distance_mm\n" + ROW, 1,
                       "missing column displacement_mm"),
    "extra column": (H + ",force_n\n" + ROW + ",1", 1, "unknown column 'force_n'"),
    "wrong order": ("phase,tendon,step,displacement_mm,tip_distance_mm\n" + ROW, 1,
                    "wrong order"),
    "no unit": ("tendon,phase,step,displacement,tip_distance_mm\n" + ROW, 1,
                "'displacement' has no unit: the units must be mm"),
    "cm": ("tendon,phase,step,displacement_mm,tip_distance_cm\n" + ROW, 1,
           "'tip_distance_cm' has unit 'cm': the units must be mm"),
    "field count": (f"{H}\n{ROW}\nflexion,pull,1,1", 3, "row has 4 fields, expected 5"),
    "tendon": (f"{H}\n{ROW}\nflex,pull,0,0,40", 3,
               "unknown tendon 'flex' (expected flexion or extension)"),
    "phase": (f"{H}\nflexion,push,0,0,40", 2, "unknown phase 'push'"),
    "not a number": (f"{H}\nflexion,pull,0,abc,40", 2, "displacement_mm is not a number"),
    "nan": (f"{H}\nflexion,pull,0,0,nan", 2, "tip_distance_mm is not finite: 'nan'"),
    "inf": (f"{H}\nflexion,pull,0,inf,40", 2, "displacement_mm is not finite: 'inf'"),
    "negative displacement": (f"{H}\nflexion,pull,0,-1,40", 2, "negative displacement_mm"),
    "zero tip": (f"{H}\nflexion,pull,0,0,0", 2, "tip_distance_mm must be > 0"),
    "negative tip": (f"{H}\nflexion,pull,0,0,-3", 2, "tip_distance_mm must be > 0"),
    "float step": (f"{H}\nflexion,pull,0.5,0,40", 2, "step is not an integer: '0.5'"),
    "duplicate step": (f"{H}\n{ROW}\nflexion,pull,1,1,40\nflexion,pull,1,2,40", 4,
                       "duplicate flexion step 1"),
    "gap": (f"{H}\n{ROW}\nflexion,pull,2,1,40", 3, "flexion step 2 after step 0 (expected 1)"),
    "not from 0": (f"{H}\nflexion,pull,1,0,40", 2, "flexion starts at step 1 (expected 0)"),
    "release first": (f"{H}\nextension,release,0,0,40", 2, "extension starts with release"),
    "pull after release": (f"{H}\n{ROW}\nflexion,release,1,0,40\nflexion,pull,2,1,40", 4,
                           "flexion pull after release"),
    "pull decreasing": (f"{H}\nflexion,pull,0,2,40\nflexion,pull,1,1,40", 3,
                        "flexion pull displacement decreases"),
    "release increasing": (f"{H}\nflexion,pull,0,2,40\nflexion,release,1,1,40\n"
                           "flexion,release,2,1.5,40", 4,
                           "flexion release displacement increases"),
    "source": (f"# source: measured\n{H}\n{ROW}", 1,
               "unknown source 'measured' (expected real, sim or illustrative)"),
    "no rows": (f"# source: real\n\n{H}\n\n", 3, "header but no data rows"),
    "header twice": (f"{H}\n{ROW}\n{H}", 3, "the header again"),
    "metadata twice": (f"# design: a\n# design: b\n{H}\n{ROW}", 2, "'design' given twice"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_malformed_logs(tmp_path, case):
    text, line, msg = BAD[case]
    path = write(tmp_path, text)
    with pytest.raises(LogError) as e:
        read_log(path)
    s = str(e.value)
    assert s.startswith(f"{path}:{line}: "), s
    assert msg in s, s
    assert "\n" not in s
    with pytest.raises(LogError, match=f"^<log>:{line}: "):
        parse_log(text)


def test_non_utf8_and_folder(tmp_path):
    path = tmp_path / "latin.csv"
    path.write_bytes(f"{H}\n".encode() + b"flexion,pull,0,0,4\xb50\n")
    with pytest.raises(LogError, match=r"latin.csv:2: not UTF-8"):
        read_log(path)
    with pytest.raises(LogError, match=r":0: is a folder"):
        read_log(tmp_path)


def test_bad_header_message_names_the_units():
    with pytest.raises(LogError) as e:
        parse_log("tendon,phase,step,displacement_in,tip_distance_mm\n" + ROW, "r.csv")
    assert str(e.value) == ("r.csv:1: bad header: column 'displacement_in' has unit 'in': the "
                            f"units must be mm (expected 'displacement_mm'); expected '{H}'")


def test_check_design():
    def log(**meta):
        return TipLog({}, dict(meta), [], "log.csv")

    a = log(design="X", design_sha="aaa")
    msg = check_design(a, "Y", "bbb")
    assert msg == "log.csv was recorded for design X (sha aaa), not Y (sha bbb)"
    assert a.warnings == [msg]
    assert check_design(log(design="X", design_sha="aaa"), "Y", "aaa") is None  # sha decides
    b = log(design="X")
    assert check_design(b, "Y", "bbb") == "log.csv was recorded for design X, not Y"
    assert check_design(log(design="X"), "X", None) is None
    assert check_design(log(), "Y", "bbb") is None
    assert check_design(log(design="X", design_sha="aaa"), None, None) is None
