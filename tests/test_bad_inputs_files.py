"""Bad files handed to ``realgap``, ``report``, ``view``, ``compare --resume``, ``generate
--base`` and ``robotize`` (docs/safety.md): a tendon log, ``params.json``, a design whose
controller the replay cannot run, an export folder's ``report.json`` and ``tendons.json``, a
design run's ``metrics.jsonl`` and ``best.npz``, a comparison's ``compare.json`` and
``cell.json``, prior weights and a ``.ply`` cloud. Each is refused with exit code 2 and one
``error:`` line naming the problem, before any simulation and before anything is written.

Every broken file is built in ``tmp_path`` from a small real input (the committed export
``exports/gripping-seed0``, its tendon log, a reference gripper design). ``view`` cases hold
the port they ask for: a case the checks missed fails on that port instead of serving.
"""

from __future__ import annotations

import json
import shutil
import socket
from pathlib import Path

import numpy as np
import pytest
from bad_input import assert_refused, snapshot
from cli_inprocess import run_cli

ROOT = Path(__file__).resolve().parents[1]
REF = ROOT / "exports" / "gripping-seed0"
LOG = REF / "tip_distance_illustrative.csv"
RUN = ROOT / "tests" / "data" / "design-run-gripping"


# ------------------------------------------------------------------------------- builders
def _log(tmp: Path, old: str, new: str) -> Path:
    """The committed log with its first ``old`` replaced by ``new``."""
    text = LOG.read_text()
    assert old in text
    path = tmp / "log.csv"
    path.write_text(text.replace(old, new, 1))
    return path


def _file(tmp: Path, name: str, content: str | bytes) -> Path:
    path = tmp / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


def _mark(folder: Path) -> None:
    """The completion marker that ``dbtool export`` writes last."""
    try:
        from dbtool.export.complete import mark_complete
    except ImportError:
        (folder / "export-complete.json").write_text('{"format": "dbtool.export/1"}')
    else:
        mark_complete(folder)


def _export(tmp: Path, files=("report.json", "report.md"), report=None, tendons=None,
            extra: dict | None = None) -> Path:
    """A copy of the committed export (``files``), ``report.json`` and ``tendons.json``
    replaced by ``report`` / ``tendons`` (text, or a function of the committed JSON)."""
    folder = tmp / "export"
    folder.mkdir()
    for name in files:
        shutil.copy(REF / name, folder)
    for name, change in (("report.json", report), ("tendons.json", tendons)):
        if change is not None:
            text = change if isinstance(change, str | bytes) else json.dumps(
                change(json.loads((REF / name).read_text())))
            _file(folder, name, text)
    for name, content in (extra or {}).items():
        _file(folder, name, content)
    _mark(folder)
    return folder


def _part(**changes):
    """report.json with the finger part's entries changed."""
    def change(r):
        r["parts"]["finger"].update(changes)
        return r
    return change


def _design(tmp: Path, controller: np.ndarray, name: str = "design.npz") -> Path:
    """The reference gripper with ``controller`` written into its file (past any check of
    :meth:`Design.save`)."""
    from dbtool.design import Design
    from dbtool.robotize.actuators import reference_robot
    from dbtool.sim.tasks import get_task

    task = get_task("gripping")
    path = Design("gripping", reference_robot(task, "finger"), task.controller()).save(
        tmp / name)
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["controller"] = controller
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    return path


def _run_folder(tmp: Path, **files) -> Path:
    """A copy of the committed design run with ``files`` (name: content) replaced."""
    folder = tmp / "run"
    shutil.copytree(RUN, folder)
    for name, content in files.items():
        _file(folder, name, content)
    return folder


CELL = {"method": "particle", "task": "gripping", "seed": 0, "status": "done",
        "metric": 0.001, "budget": "smoke", "wall_s": 1.0}
COMPARE = {"format": "dbtool.compare/1", "budget": "smoke", "threads": 1, "arch": "cpu",
           "cells": [["particle", "gripping", 0]]}


def _comparison(tmp: Path, compare=None, cell=None, metrics: str | None = None) -> Path:
    """A comparison of one cell: ``compare.json``, the cell's ``cell.json`` (dicts are
    written as JSON, texts as they are) and its ``metrics.jsonl``."""
    folder = tmp / "comparison"
    cell_dir = folder / "cells" / "particle-gripping-s0"
    cell_dir.mkdir(parents=True)
    if metrics is not None:
        (cell_dir / "metrics.jsonl").write_text(metrics)
    for path, data in ((folder / "compare.json", COMPARE if compare is None else compare),
                       (cell_dir / "cell.json", CELL if cell is None else cell)):
        path.write_text(data if isinstance(data, str) else json.dumps(data))
    return folder


def _weights(tmp: Path, checkpoint) -> Path:
    import torch

    path = tmp / "base.pt"
    if isinstance(checkpoint, bytes):
        path.write_bytes(checkpoint)
    else:
        torch.save(checkpoint, path)
    return path


def _nan_weights(tmp: Path) -> Path:
    import torch

    ck = torch.load(ROOT / "dbtool" / "prior" / "weights" / "v1" / "base.pt",
                    weights_only=True, map_location="cpu")
    next(iter(ck["state"].values())).view(-1)[0] = float("nan")
    return _weights(tmp, ck)


def _ply(tmp: Path, rows: list[str]) -> Path:
    header = (f"ply\nformat ascii 1.0\nelement vertex {len(rows)}\nproperty float x\n"
              "property float y\nproperty float z\nend_header\n")
    return _file(tmp, "cloud.ply", header + "\n".join(rows) + "\n")


# ------------------------------------------------------------------------------- the cases
def replay(log=None, params=None):
    """``realgap replay LOG --design REF [--params P] -o out``."""
    def args(tmp):
        a = ["realgap", "replay", str(log(tmp) if log else LOG), "--design", str(REF),
             "-o", str(tmp / "out")]
        return a + (["--params", str(params(tmp))] if params else [])
    return args


def calibrate(log):
    return lambda tmp: ["realgap", "calibrate", str(log(tmp)), "--design", str(REF), "-o",
                        str(tmp / "out"), "--max-evals", "1"]


def params(content):
    return replay(params=lambda tmp: _file(tmp, "params.json", content))


def on_design(folder):
    """``realgap replay`` of the committed log on the design in ``folder(tmp)``."""
    return lambda tmp: ["realgap", "replay", str(LOG), "--design", str(folder(tmp)), "-o",
                        str(tmp / "out")]


def report(path):
    return lambda tmp: ["report", str(path(tmp))]


def view(path, host=None):
    return lambda tmp: ["view", str(path(tmp)), *(["--host", host] if host else [])]


def resume(compare=None, cell=None, metrics=None):
    return lambda tmp: ["compare", "--preset", "smoke", "--resume", "--out",
                        str(_comparison(tmp, compare, cell, metrics))]


def generate(checkpoint):
    return lambda tmp: ["generate", "a star", "-n", "1", "--base",
                        str(checkpoint(tmp) if callable(checkpoint) else
                            _weights(tmp, checkpoint)), "-o", str(tmp / "out")]


def robotize(rows):
    return lambda tmp: ["robotize", str(_ply(tmp, rows)), "--task", "gripping", "-o",
                        str(tmp / "robot.npz")]


GOOD_ROWS = [f"{x:.3f} {y:.3f} {z:.3f}" for x, y, z in
             np.random.default_rng(0).uniform(-0.4, 0.4, (80, 3))]

CASES = {
    # 1. tendon logs: non-physical readings
    "log: tip distance 1e300": (replay(lambda t: _log(t, "77.251", "1e300")),
                                "tip_distance_mm 1e300 is more than"),
    "log: tip distance 1e300 (calibrate)": (calibrate(lambda t: _log(t, "77.251", "1e300")),
                                            "tip_distance_mm 1e300"),
    "log: tip distance inf": (replay(lambda t: _log(t, "77.251", "inf")), "not finite"),
    "log: tip distance nan": (replay(lambda t: _log(t, "77.251", "nan")), "not finite"),
    "log: negative tip distance": (replay(lambda t: _log(t, "77.251", "-3")), "must be > 0"),
    "log: absurd displacement": (replay(lambda t: _log(t, "pull,5,10.0", "pull,5,1e9")),
                                 "displacement_mm 1e9 is more than"),
    "log: negative displacement": (replay(lambda t: _log(t, "pull,1,2.0", "pull,1,-2.0")),
                                   "negative displacement_mm"),
    # 2. params.json
    "params: gain a text": (params('{"params": {"gain": "1.3"}}'), "gain must be a number"),
    "params: gain null": (params('{"gain": null}'), "gain must be a number, not null"),
    "params: gain true": (params('{"gain": true}'), "gain must be a number, not true"),
    "params: gain NaN": (params('{"gain": NaN}'), "gain must be a finite number"),
    "params: gain 1e999": (params('{"gain": 1e999}'), "gain must be a finite number"),
    "params: stiffness beyond the bench": (params('{"stiffness_scale": 1e6}'),
                                           "stiffness_scale must be at most"),
    "params: negative friction": (params('{"friction_mm": -1}'), "friction_mm must be >= 0"),
    "params: not JSON": (params("gain = 1.3"), "not valid JSON"),
    "params: a list": (params("[1.3, 1.0]"), "expected a JSON object"),
    "params: params a list": (params('{"params": [1.3]}'), "expected a JSON object"),
    "params: unknown key": (params('{"gian": 1.3}'), "unknown parameter(s) 'gian'"),
    "params: not UTF-8": (params(b'{"gain": "\xff"}'), "not UTF-8"),
    # 3. a controller the replay cannot run
    "report: controller (0, 2)": (report(lambda t: _design(t, np.zeros((0, 2)))),
                                  "controller"),
    "view: controller (0, 2)": (view(lambda t: _design(t, np.zeros((0, 2)))), "controller"),
    "report: controller of 3 groups": (report(lambda t: _design(t, np.zeros((5, 3)))),
                                       "controller"),
    "report: controller of strings": (report(lambda t: _design(t, np.full((5, 2), "x"))),
                                      "controller"),
    "report: run's metrics.jsonl garbled": (
        report(lambda t: _run_folder(t, **{"metrics.jsonl": '{"phase": "embedding"\n'})),
        "metrics.jsonl:1: not a JSON line"),
    "report: run's metrics row of strings": (
        report(lambda t: _run_folder(t, **{"metrics.jsonl": json.dumps(
            {"phase": "embedding", "epoch": 0, "mean": "0.1", "max": 0.2}) + "\n"})),
        "mean must be a number"),
    "report: run's config.json a list": (report(lambda t: _run_folder(
        t, **{"config.json": "[]"})), "config.json must hold a JSON object"),
    "view: run's best.npz garbled": (view(lambda t: _run_folder(
        t, **{"best.npz": b"PK\x03\x04 not a zip"})), "best.npz is not a readable"),
    "view: run's trajectory.npz of the wrong shape": (view(lambda t: _run_folder(
        t, **{"trajectory.npz": _npz(t=np.arange(3), sample=np.arange(2),
                                     metric=np.zeros(2), xt=np.zeros((2, 3, 10)),
                                     x0=np.zeros((2, 3, 10, 3)))})),
        "xt has shape"),
    # 4. export folders
    "report: report.json garbage": (report(lambda t: _export(t, report="{not json")),
                                    "report.json: not valid JSON"),
    "view: report.json garbage": (view(lambda t: _export(t, report="{not json")),
                                  "report.json: not valid JSON"),
    "report: report.json a list": (report(lambda t: _export(t, report="[1, 2]")),
                                   "report.json must hold a JSON object"),
    "view: report.json a list": (view(lambda t: _export(t, report="[]")),
                                 "report.json must hold a JSON object"),
    "report: report.json not UTF-8": (report(lambda t: _export(t, report=b"\xff\xfe{}")),
                                      "report.json: not UTF-8"),
    "report: parts a list": (report(lambda t: _export(t, report=lambda r: {**r, "parts": [1]})),
                             "parts must be an object"),
    "view: a part a text": (view(lambda t: _export(
        t, report=lambda r: {**r, "parts": {"finger": "big"}})), "parts.finger must be"),
    "report: volume as a text": (report(lambda t: _export(t, report=_part(volume_mm3="1e5"))),
                                 "parts.finger.volume_mm3 must be a number"),
    "report: bbox as a text": (report(lambda t: _export(t, report=_part(bbox_mm="60x72"))),
                               "parts.finger.bbox_mm must be a list of 3 numbers"),
    "report: watertight a text": (report(lambda t: _export(t, report=_part(watertight="yes"))),
                                  "watertight must be true or false"),
    "view: print pose singular": (view(lambda t: _export(t, report=_part(
        print_pose={"matrix": [[0] * 4] * 4}))), "print_pose.matrix is not invertible"),
    "view: part name leaves the folder": (view(lambda t: _export(t, report=lambda r: {
        **r, "parts": {"../../finger": r["parts"]["finger"]}})), "part name"),
    "report: tendons without all_ok": (report(lambda t: _export(t, report=lambda r: {
        **r, "tendons": {"count": 4}})), "all_ok is missing"),
    "report: mm_per_sim_unit a text": (report(lambda t: _export(t, report=lambda r: {
        **r, "mm_per_sim_unit": "1000"})), "mm_per_sim_unit must be a number"),
    "report: tendons.json a list": (report(lambda t: _export(t, tendons="[1]")),
                                    "tendons.json must hold a JSON object"),
    "view: tendon point of 2 numbers": (view(lambda t: _export(t, tendons=lambda j: {
        **j, "tendons": [{**j["tendons"][0], "points": [[1, 2]]}]})),
        "points[0] must be a list of 3 numbers"),
    "report: assembly.stl garbage": (report(lambda t: _export(
        t, extra={"assembly.stl": "solid nothing\nendsolid\n"})), "holds no triangles"),
    "report: report.md not UTF-8": (report(lambda t: _export(
        t, extra={"report.md": b"\xff\xfe\x00"})), "report.md: not UTF-8"),
    "realgap: tendons.json group beyond the design": (on_design(lambda t: _export(
        t, ("report.json", "report.md", "design.npz"), tendons=lambda j: {
            **j, "tendons": [{**x, "group": 7} for x in j["tendons"]]})), "actuator group 7"),
    "realgap: export scale a text": (on_design(lambda t: _export(
        t, ("report.json", "report.md", "design.npz"),
        report=lambda r: {**r, "mm_per_sim_unit": "1000"})), "mm_per_sim_unit"),
    # 5. a host that is not this machine's
    "view: unknown host": (view(lambda t: _design(t, np.zeros((3, 2))),
                                host="no-such-host.invalid"), "--host no-such-host.invalid"),
    # 6. comparisons, prior weights, clouds
    "report: compare.json garbage": (report(lambda t: _comparison(t, "{x")),
                                     "compare.json: not valid JSON"),
    "report: compare.json cells a text": (report(lambda t: _comparison(
        t, {**COMPARE, "cells": "all"})), "is not a comparison file"),
    "view: compare.json cell leaves the folder": (view(lambda t: _comparison(
        t, {**COMPARE, "cells": [["../..", "gripping", 0]]})), "cells[0] method"),
    "report: compare.json budget_settings a list": (report(lambda t: _comparison(
        t, {**COMPARE, "budget_settings": [20]})), "budget_settings must be an object"),
    "report: cell.json a list": (report(lambda t: _comparison(t, cell="[1]")),
                                 "cell.json must hold a JSON object"),
    "view: cell.json metric a text": (view(lambda t: _comparison(
        t, cell={**CELL, "metric": "0.5"})), "metric must be a number"),
    "resume: compare.json a list": (resume(compare="[1]"), "compare.json must hold"),
    "resume: compare.json without budget": (resume(compare={
        k: v for k, v in COMPARE.items() if k != "budget"}), "budget is missing"),
    "resume: threads a text": (resume(compare={**COMPARE, "threads": "1"}),
                               "threads must be an integer"),
    "resume: unknown method": (resume(compare={**COMPARE, "cells": [["nomethod", "gripping",
                                                                      0]]}),
                               "unknown method 'nomethod'"),
    "resume: cell.json garbled": (resume(cell="{"), "cell.json: not valid JSON"),
    "resume: done cell.json with a text metric": (resume(cell={**CELL, "metric": "x"}),
                                                  "metric must be a number"),
    "resume: done cell's metrics.jsonl garbled": (resume(metrics='{"units": 1, "metric"\n'),
                                                  "metrics.jsonl:1: not a JSON line"),
    "resume: done cell's metrics units a text": (resume(metrics=json.dumps(
        {"phase": "gradient", "units": "one", "metric": 0.1}) + "\n"),
        "units or metric is not a number"),
    "generate: weights not a checkpoint": (generate(b"not a checkpoint"),
                                           "not a readable checkpoint"),
    "generate: weights without a kind": (generate({"state": {}, "model": {}}),
                                         "does not say which model"),
    "generate: model width a text": (generate({"kind": "base", "state": {},
                                               "model": {"width": "128"}}),
                                     "width must be an integer"),
    "generate: a huge model": (generate({"kind": "base", "state": {},
                                         "model": {"width": 10**7}}),
                               "width must be an integer from 0 to"),
    "generate: a training config not a dict": (generate({"ema": {}, "config": 3}),
                                               "config is not a dictionary"),
    "generate: NaN weights": (generate(_nan_weights), "NaN or infinite"),
    "robotize: cloud not a PLY": (lambda t: ["robotize", str(_file(t, "c.ply", "hello")),
                                             "--task", "gripping", "-o", str(t / "r.npz")],
                                  "not a readable PLY"),
    "robotize: cloud with NaN": (robotize(GOOD_ROWS[:-1] + ["nan 0 0"]), "NaN or infinite"),
}


def _npz(**arrays) -> bytes:
    import io

    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


@pytest.fixture
def busy_port():
    """A port this test holds (listening) for ``view``: a bad input the checks missed fails
    there, instead of starting a viewer that never returns."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


@pytest.mark.parametrize("case", list(CASES))
def test_a_bad_file_is_one_line_and_writes_nothing(case, tmp_path, busy_port):
    build, words = CASES[case]
    args = build(tmp_path)
    if args[0] == "view":
        args += ["--port", str(busy_port)]
    before = snapshot(tmp_path)
    out = run_cli(*args, cwd=tmp_path)
    assert_refused(out, tmp_path, before, words)


def test_there_are_enough_cases():
    assert len(CASES) >= 25


# ------------------------------------------------------------------------------- warnings
def test_params_outside_the_calibrated_range_warn(tmp_path):
    """A gain of 7 is legal (the calibration searches 0.2 .. 5): a warning, before the run
    (which here stops on a bad log line)."""
    p = _file(tmp_path, "params.json", '{"gain": 7}')
    log = _log(tmp_path, "77.251", "-1")
    out = run_cli("realgap", "replay", str(log), "--design", str(REF), "--params", str(p),
                  "-o", str(tmp_path / "out"), cwd=tmp_path)
    assert out.returncode == 2 and "must be > 0" in out.stderr
    from dbtool.realgap.protocol import TendonParams

    assert TendonParams.load(p).gain == 7.0
    assert TendonParams.load(p).warnings() and "gain 7" in TendonParams.load(p).warnings()[0]


def test_a_pull_past_the_strain_cap_warns():
    """100 mm on the reference finger's 72.5 mm strip: legal, but past the strain cap (0.6 at
    43.5 mm), so the simulated finger cannot follow; the committed log stays well inside."""
    from dbtool.realgap.log import parse_log, read_log
    from dbtool.realgap.protocol import TendonParams, check_strain
    from dbtool.realgap.run import open_bench

    bench, _ = open_bench(REF)
    log = parse_log("# source: real\ntendon,phase,step,displacement_mm,tip_distance_mm\n"
                    "flexion,pull,0,0,77\nflexion,pull,1,100,60\n", "far.csv")
    (line,) = check_strain(bench, log, TendonParams())
    assert "flexion is pulled up to 100 mm, beyond the 43.5 mm" in line
    assert log.warnings == [line]
    assert check_strain(bench, read_log(LOG), TendonParams()) == []


def test_a_calibrated_params_file_still_loads(tmp_path):
    from dbtool.realgap.protocol import TendonParams

    p = _file(tmp_path, "params.json", json.dumps(
        {"params": {"gain": 1.3, "stiffness_scale": 1, "friction_mm": 1.2, "slack_mm": 0},
         "stderr": {"gain": 0.1}, "rmse_after_mm": 0.2}))
    assert TendonParams.load(p) == TendonParams(1.3, 1.0, 1.2, 0.0)
    assert TendonParams.load(p).warnings() == []


def test_the_committed_files_pass_the_checks():
    """The checks accept what dbtool wrote: the shipped export, comparisons and weights."""
    import glob

    from dbtool.compare.cells import read_cell, read_compare_json
    from dbtool.compare.page import read_comparison
    from dbtool.export.reports.page import read_export_report, read_tendons
    from dbtool.report_run import load_design, run_files

    assert read_export_report(REF)["parts"] and read_tendons(REF)["tendons"]
    for path in glob.glob(str(ROOT / "docs" / "results" / "*" / "compare.json")):
        read_compare_json(path, resume=True)
        assert read_comparison(Path(path).parent).cells
    for path in glob.glob(str(ROOT / "docs" / "results" / "*" / "cells" / "*")):
        read_cell(Path(path))
    assert run_files(RUN) and len(load_design(RUN / "design.npz").controller) > 0


# ------------------------------------------------------------------------------- IPv6
def _ipv6() -> bool:
    try:
        with socket.socket(socket.AF_INET6) as s:
            s.bind(("::1", 0))
        return True
    except OSError:
        return False


@pytest.mark.skipif(not _ipv6(), reason="no IPv6 loopback here")
def test_the_viewer_binds_ipv6_loopback():
    """``--host ::1`` (listed as loopback) passes the port check, a port in use there is the
    usual one-line error, and the viewer serves at ``http://[::1]:PORT``."""
    import urllib.request

    from dbtool.errors import InputError
    from dbtool.view_run import LOOPBACK
    from dbtool.viz.viewer import check_port

    assert "::1" in LOOPBACK
    with socket.socket(socket.AF_INET6) as s:
        s.bind(("::1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(InputError, match=f"port {port} on ::1 is not available"):
            check_port("::1", port)
    check_port("::1", port)
    check_port("[::1]", port)
    pytest.importorskip("viser")
    from dbtool.viz.viewer import open_server, url_of

    server = open_server("::1", port, "ipv6")
    try:
        url = url_of(server, "::1")
        assert url == f"http://[::1]:{port}"
        with urllib.request.urlopen(url, timeout=20) as page:
            assert page.status == 200
    finally:
        server.stop()
