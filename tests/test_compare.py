"""``dbtool compare`` run as a user would (docs/results.md): the smoke budget with every method
and every executor, a resume after a kill, bad input, and the budget arithmetic of every method.

The runs use gripping, the task whose cells are the cheapest (its fingers are a few thousand
particles); a multi-task table is checked on a results file (``test_compare_report.py``).

The CLI runs in subprocesses: a comparison sets Taichi and torch to one thread, which must not
leak into the pytest process.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from cli_inprocess import run_cli

from dbtool.cli.compare import expand_list_options
from dbtool.compare.budget import BUDGETS, GRAD_COST, get_budget, gradient_iterations, used
from dbtool.compare.methods import (
    GRADIENT,
    METHODS,
    TITLES,
    diffusebot_configs,
    diffusebot_plan,
    paper_configs,
    paper_plan,
)
from dbtool.design import Design
from dbtool.sim.tasks import TASKS, get_task

CLI = [sys.executable, "-c", "from dbtool.cli import main; main()", "compare"]
NO_RAY = [sys.executable, "-c", "import sys; sys.modules['ray'] = None; "
          "from dbtool.cli import main; main()", "compare"]
SMOKE = ["--preset", "smoke", "--seed", "0"]
TASK = "gripping"
ALL = ["--task", TASK, "--method", "all"]  # as a user types it
# what must not depend on where a cell ran (wall_s, worker and commit may)
SAME = ("method", "task", "seed", "status", "metric", "budget_units", "budget_used",
        "forward_episodes", "gradient_episodes", "error")
CELL_FILES = ("design.npz", "metrics.jsonl", "montage.png", "cell.json")
ENV = {**os.environ, "MPLBACKEND": "Agg", "TI_LOG_LEVEL": "warn", "PYTHONUNBUFFERED": "1"}


def _compare(*args: str, cwd: Path | None = None, cmd: list[str] = CLI,
             timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run([*cmd, *args], capture_output=True, text=True, cwd=cwd, env=ENV,
                          timeout=timeout)


def _rows(folder: Path) -> list[dict]:
    with open(folder / "results.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _same(rows: list[dict]) -> dict[tuple, tuple]:
    return {(r["method"], r["task"], r["seed"]): tuple(r[c] for c in SAME) for r in rows}


def _cell(folder: Path, method: str, task: str, seed: int = 0) -> Path:
    return folder / "cells" / f"{method}-{task}-s{seed}"


def _tree(root: Path) -> dict[str, tuple[int, bytes]]:
    """Every file and folder under ``root`` with its mtime and content."""
    return {str(p.relative_to(root)): (p.stat().st_mtime_ns,
                                       p.read_bytes() if p.is_file() else b"")
            for p in sorted(root.rglob("*"))}


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """The uninterrupted serial smoke comparison of gripping, all six methods."""
    out = tmp_path_factory.mktemp("compare") / "serial"
    res = _compare(*SMOKE, *ALL, "--executor", "serial", "--out", str(out))
    assert res.returncode == 0, res.stderr[-3000:]
    return out, res


def test_serial_smoke_comparison(serial_run):
    out, res = serial_run
    rows = _rows(out)
    assert [(r["task"], r["method"]) for r in rows] == [
        (TASK, m) for m in METHODS]
    assert {r["status"] for r in rows} == {"done"} and {r["error"] for r in rows} == {""}
    assert "6 cells done, 0 failed, 0 already finished" in res.stdout
    units = get_budget("smoke").units
    for r in rows:
        assert float(r["budget_units"]) == units == 8
        assert float(r["budget_used"]) <= units
        fwd, grad = int(r["forward_episodes"]), int(r["gradient_episodes"])
        assert float(r["budget_used"]) == used(fwd, grad)
        if r["method"] in GRADIENT:  # one gradient episode and the final evaluation
            assert (fwd, grad) == (2, gradient_iterations(units)) == (2, 1)
        elif r["method"] == "prior":  # units - 1 samples and the final evaluation
            assert (fwd, grad) == (units, 0)
        cell = _cell(out, r["method"], r["task"])
        progress = [json.loads(line) for line in (cell / "metrics.jsonl").read_text()
                    .splitlines()]
        if r["method"] not in GRADIENT and r["method"] != "prior":
            # two epochs of one design, one refinement step (a gradient episode, counted as
            # a forward and a backward, and a line search of one length, none where the
            # gradient is zero), the final evaluation
            search = [len(p["search"]) for p in progress if p["phase"] == "refine"]
            assert len(search) == 1 and search[0] in (0, 1)
            assert (fwd, grad) == (2 + 1 + search[0] + 1, 1)
            planned = diffusebot_plan(r["task"], get_budget("smoke"))["planned_units"]
            assert float(r["budget_used"]) == planned - 1 + search[0]
        for name in CELL_FILES:
            assert (cell / name).stat().st_size > 0, cell / name
        rec = json.loads((cell / "cell.json").read_text())
        assert rec["status"] == "done" and repr(float(rec["metric"])) == r["metric"]
        assert Design.load(cell / "design.npz").metrics == {r["task"]: float(r["metric"])}
        assert progress[-1] == {"phase": "final", "metric": float(r["metric"]),
                                "units": float(r["budget_used"])}
        spent = [row["units"] for row in progress]  # every row: the units spent by then
        assert spent == sorted(spent) and spent[0] > 0
        if r["method"] == "prior":  # one row per scored sample, one unit each
            assert spent[:-1] == [float(k) for k in range(1, units)]
    for name in ("table.md", "bars.png", "robots.png", "anytime.png", f"anytime-{TASK}.png"):
        assert (out / name).stat().st_size > 0
        assert f"{out / name}" in res.stdout
    table = (out / "table.md").read_text().splitlines()
    assert table[0] == "| method | Gripping | mean rank |"
    assert [line.split(" | ")[0] for line in table[2:8]] == [f"| {TITLES[m]}" for m in METHODS]
    assert "1 seed per cell, budget 8 forward-episode units per cell." in table[-1]


def test_ray_executor_gives_the_serial_numbers(serial_run, tmp_path):
    """The prior (which samples the diffusion model) on two Ray workers; the local executor's
    test runs the gradient baseline, so each kind of method runs outside the caller."""
    out = tmp_path / "ray"
    methods = ("prior",)
    res = _compare(*SMOKE, "--task", TASK, "--method", *methods, "--executor", "ray",
                   "--workers", "2", "--out", str(out))
    assert res.returncode == 0, res.stderr[-3000:]
    assert "1 cells, 0 finished, 1 to run on ray" in res.stdout
    rows = _rows(out)
    assert [r["method"] for r in rows] == list(methods)
    assert {r["status"] for r in rows} == {"done"}
    serial = _same(_rows(serial_run[0]))
    assert _same(rows) == {(m, TASK, "0"): serial[(m, TASK, "0")] for m in methods}
    for name in ("table.md", "bars.png", "robots.png"):
        assert (out / name).stat().st_size > 0
    for r in rows:
        for name in CELL_FILES:
            assert (_cell(out, r["method"], r["task"]) / name).stat().st_size > 0


def test_local_executor_gives_the_serial_numbers(serial_run, tmp_path):
    """The gradient baseline in a worker process (the Ray test runs the prior)."""
    out = tmp_path / "local"
    res = _compare(*SMOKE, "--task", TASK, "--method", "particle", "--executor", "local",
                   "--workers", "2", "--out", str(out))
    assert res.returncode == 0, res.stderr[-3000:]
    rows = _rows(out)
    serial = _same(_rows(serial_run[0]))
    assert _same(rows) == {k: serial[k] for k in (("particle", TASK, "0"),)}
    assert "1 cells done, 0 failed, 0 already finished" in res.stdout


def test_a_method_that_does_not_read_the_seed_runs_once_per_task(serial_run, tmp_path):
    """particle and voxel start from the reference body and descend deterministically: their
    cells at other seeds are copies of one run, marked as such, and a run of seed 1 on its own
    gives seed 0's numbers (what makes the copy true)."""
    from dbtool.baselines.registry import make
    from dbtool.compare.methods import seeded

    assert [m for m in METHODS if not seeded(m)] == ["particle", "voxel"]
    assert [m for m in METHODS if not seeded(m, get_budget("quick"))] == ["particle", "voxel"]
    assert all(seeded(m, get_budget("standard")) for m in METHODS)  # a seeded start
    task = get_task(TASK)
    for m in GRADIENT:
        a, b = make(m, task, seed=0), make(m, task, seed=3)
        same = all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters(), strict=True))
        assert same == (not seeded(m)), m
    out = tmp_path / "seeds"  # seeds 1 and 2 without 0: the run of seed 1 is the one copied
    res = _compare("--preset", "smoke", "--task", TASK, "--method", "particle",
                   "--seed", "1", "2", "--out", str(out))
    assert res.returncode == 0, res.stderr[-3000:]
    assert "2 cells, 0 finished, 1 to run on serial, 1 to copy" in res.stdout
    rows = _rows(out)
    assert len({tuple(v[3:]) for v in _same(rows).values()}) == 1
    assert rows[1]["worker"] == f"copy of particle-{TASK}-s1"
    rec = json.loads((_cell(out, "particle", TASK, 2) / "cell.json").read_text())
    assert rec["seed"] == 2 and rec["copied_from"] == f"particle-{TASK}-s1"
    for name in CELL_FILES:
        assert (_cell(out, "particle", TASK, 2) / name).stat().st_size > 0
    # seed 1 ran on its own and gives the serial run's seed-0 numbers
    assert rows[0]["metric"] == _same(_rows(serial_run[0]))[("particle", TASK, "0")][4]


def _children(pid: int) -> set[int]:
    out = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.add(int(stat.parent.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process table in /proc")
def test_local_workers_exit_when_the_comparison_is_killed(tmp_path):
    """A SIGKILLed ``dbtool compare`` cannot shut its pool down: its local workers notice the
    parent is gone and exit instead of computing cells nobody collects."""
    out = tmp_path / "orphans"
    proc = subprocess.Popen([*CLI, *SMOKE, "--task", TASK, "--method", "particle",
                             "--method", "prior", "--executor", "local", "--workers", "2",
                             "--out", str(out)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=ENV)
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and proc.poll() is None and not (
                (out / "cells").is_dir() and len(list((out / "cells").iterdir())) == 2):
            time.sleep(0.2)  # both workers have started a cell
        workers = _children(proc.pid)
    finally:
        proc.kill()
        proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL and len(workers) >= 2
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and any(_alive(w) for w in workers):
        time.sleep(0.5)
    assert not any(_alive(w) for w in workers), "workers outlived the comparison"


def test_resume_after_a_kill_skips_the_finished_cell(serial_run, tmp_path):
    out = tmp_path / "killed"
    methods = ("particle", "prior")
    args = [*SMOKE, "--task", TASK, *(a for m in methods for a in ("--method", m)),
            "--executor", "serial", "--out", str(out)]
    first = _cell(out, "particle", TASK) / "cell.json"
    proc = subprocess.Popen([*CLI, *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=ENV)
    try:
        deadline = time.monotonic() + 600
        while not first.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        proc.kill()  # SIGKILL: no cleanup of any kind
        proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    assert [m for m in methods if (_cell(out, m, TASK) / "cell.json").exists()] == [
        "particle"]
    before = first.stat().st_mtime_ns, first.read_bytes()
    wall = json.loads(before[1])["wall_s"]

    # a resume that names cells runs only those: particle is finished, prior was not asked for
    res = _compare("--resume", "--out", str(out), "--executor", "serial", "--method",
                   "particle")
    assert res.returncode == 0, res.stderr[-3000:]
    assert "2 cells, 1 finished, 0 to run on serial (budget smoke)" in res.stdout
    assert not (_cell(out, "prior", TASK) / "cell.json").exists()

    res = _compare("--resume", "--out", str(out), "--executor", "serial")
    assert res.returncode == 0, res.stderr[-3000:]
    assert "2 cells, 1 finished, 1 to run on serial (budget smoke)" in res.stdout
    assert "1 cells done, 0 failed, 1 already finished" in res.stdout
    assert (first.stat().st_mtime_ns, first.read_bytes()) == before
    rows = _rows(out)
    assert [r["method"] for r in rows] == list(methods)
    assert rows[0]["wall_s"] == str(wall)
    serial = _same(_rows(serial_run[0]))
    assert _same(rows) == {(m, TASK, "0"): serial[(m, TASK, "0")] for m in methods}
    for m in methods:  # the rerun cells have one run's progress rows, not two
        log = (_cell(out, m, TASK) / "metrics.jsonl").read_text()
        assert log == (_cell(serial_run[0], m, TASK) / "metrics.jsonl").read_text()


def _fake_comparison(folder: Path) -> None:
    folder.mkdir()
    (folder / "compare.json").write_text(json.dumps(
        {"format": "dbtool.compare/1", "budget": "smoke", "threads": 1, "arch": "cpu",
         "cells": [["particle", "crawling", 0]]}))


def _with_file(folder: Path) -> None:
    folder.mkdir()
    (folder / "notes.txt").write_text("not a comparison\n")


ONE = ["--preset", "smoke", "--task", TASK, "--method", "particle"]
BAD = {
    "unknown method": (["--preset", "smoke", "--method", "nosuch", "--out", "new"], None,
                       "'nosuch' is not one of 'particle', 'voxel', 'implicit', 'cppn', "
                       "'prior', 'diffusebot', 'embedding', 'codesign', 'diffusebot-paper', "
                       "'all'"),
    "unknown method, old spelling": (["--budget", "smoke", "--methods", "nosuch", "--out",
                                      "new"], None,
                                     "unknown method 'nosuch'; choose from particle, voxel, "
                                     "implicit, cppn, prior, diffusebot, embedding, codesign, "
                                     "diffusebot-paper or all"),
    "unknown task": (["--preset", "smoke", "--task", "walking", "--out", "new"], None,
                     "'walking' is not one of 'balancing'"),
    "unknown budget": (["--preset", "huge", "--out", "new"], None,
                       "'huge' is not one of 'smoke', 'quick', 'standard', 'paper'"),
    "unknown executor": ([*ONE, "--executor", "nope", "--out", "new"], None,
                         "'nope' is not one of 'serial', 'local', 'ray'"),
    "resume without out": ([*ONE, "--resume"], None, "--resume needs --out"),
    "resume a missing folder": ([*ONE, "--resume", "--out", "new"], None,
                                "nothing to resume"),
    "resume a folder that is no comparison": ([*ONE, "--resume", "--out", "other"], _with_file,
                                              "is not a comparison folder"),
    "resume on another budget": (["--preset", "quick", "--resume", "--out", "other"],
                                 _fake_comparison, "was run with --preset smoke --threads 1"),
    "new comparison in a non-empty folder": ([*ONE, "--out", "other"], _with_file,
                                             "already exists and is not empty"),
    "unreachable ray": ([*ONE, "--executor", "ray", "--address", "127.0.0.1:1", "--out", "new"],
                        None, "cannot reach the Ray cluster at 127.0.0.1:1"),
    "ray not installed": ([*ONE, "--executor", "ray", "--out", "new"], None,
                          "pip install 'dbtool[cluster]'"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_input_is_one_error_line_and_touches_nothing(case, tmp_path):
    args, setup, message = BAD[case]
    if setup:
        setup(tmp_path / "other")
    before = _tree(tmp_path)
    start = time.monotonic()
    if "ray" in case:  # Ray's import and connection stay out of the test process
        res = _compare(*args, cwd=tmp_path, cmd=NO_RAY if case == "ray not installed" else CLI,
                       timeout=120)
    else:
        res = run_cli("compare", *args, cwd=tmp_path)
    assert time.monotonic() - start < 60
    assert res.returncode == 2, (res.stdout, res.stderr)
    errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], res.stderr
    assert "Traceback" not in res.stderr and "comparison" not in res.stdout
    assert _tree(tmp_path) == before


def test_space_separated_lists_reach_every_value(tmp_path):
    """``--tasks a b`` works like ``--tasks a --tasks b``: the second value is read (and here
    refused by name), not dropped or taken for an argument."""
    res = _compare("--task", TASK, "nosuchtask", "--seed", "0", "1", "--out", "new",
                   cwd=tmp_path, timeout=120)
    assert res.returncode == 2 and "'nosuchtask' is not one of" in res.stderr, res.stderr
    assert list(tmp_path.iterdir()) == []
    assert expand_list_options(["compare", "--method", "prior", "diffusebot", "--seed", "0",
                                "1", "--preset", "smoke", "--out", "d"]) == [
        "compare", "--method", "prior", "--method", "diffusebot", "--seed", "0", "--seed",
        "1", "--preset", "smoke", "--out", "d"]
    assert expand_list_options(["design", "gripping"]) == ["design", "gripping"]


# ------------------------------------------------------------------------- budget arithmetic
REFINE_PLANS = {  # (epochs, samples per epoch, refinement steps, line search, planned units)
    "smoke": (2, 1, 1, 1, 8), "quick": (2, 6, 1, 3, 20), "standard": (4, 14, 6, 3, 99),
    "paper": (20, 62, 178, 3, 2487)}
PLANS = {  # (epochs, samples per epoch, co-design samples, Langevin steps, planned units)
    "smoke": {t: (2, 1, 1, 1, 8) for t in TASKS},
    "quick": {t: (2, 5, 1, 1, 19) for t in TASKS},
    "standard": {t: (4, 14, 1, 6, 100) for t in TASKS},  # 3 designs per epoch per epoch
    "paper": {"balancing": (20, 60, 4, 27, 1961), "landing": (20, 60, 4, 21, 1793),
              **{t: (20, 60, 4, 45, 2465) for t in ("crawling", "hurdling", "gripping", "box")}},
}


@pytest.mark.parametrize("name", BUDGETS)
def test_every_method_fits_the_budget(name):
    from dbtool.codesign.config import TABLE5, n_steps
    from dbtool.codesign.langevin import stops

    budget = get_budget(name)
    assert used(3, 2) == 3 + 2 * (GRAD_COST - 1) == 9.0
    n = gradient_iterations(budget.units)
    assert n == {"smoke": 1, "quick": 4, "standard": 24, "paper": 624}[name]
    assert used(n + 1, n) <= budget.units < used(n + 2, n + 1)  # all that fits, and no more
    for task in TASKS:
        plan = paper_plan(task, budget)
        sizes = (plan["epochs"], plan["samples_per_epoch"], plan["codesign_samples"],
                 plan["langevin_steps"], plan["planned_units"])
        assert sizes == PLANS[name][task]
        assert plan["preset"] == ("paper" if name == "paper" else "quick")
        assert plan["planned_units"] <= budget.units
        emb, cod, _ = paper_configs(task, budget)
        search = len(cod.search)  # forward episodes of each step's line search
        assert search == {"smoke": 0, "quick": 3, "standard": 3, "paper": 3}[name]
        assert plan["planned_units"] == (
            plan["epochs"] * plan["samples_per_epoch"] + 1
            + plan["codesign_samples"] * used(plan["langevin_steps"] * (1 + search) + 1,
                                              plan["langevin_steps"]))
        assert (emb.epochs, emb.samples_per_epoch, cod.samples, n_steps(cod)) == sizes[:4]
        assert emb.sample_steps == budget.sample_steps and cod.refine == 0
        assert emb.signal == 0.0  # as published: the embedding trains on every epoch
        if name in ("smoke", "quick"):  # one stop: at t_min with the line search, else t_max
            assert stops(cod) == [0 if search else TABLE5[task].t_max]
        elif name == "standard":  # six stops spread over Table 5's [t_min, t_max]
            st = stops(cod)
            assert len(st) == 6 and st[0] == TABLE5[task].t_max and st[-1] == TABLE5[task].t_min
        # DiffuseBot: the same epochs as the published plan where it is sized to the budget,
        # the rest on refinement steps of the elite (a gradient episode and a line search)
        new = diffusebot_plan(task, budget)
        emb2, ref, _ = diffusebot_configs(task, budget)
        assert (new["epochs"], new["samples_per_epoch"], new["refine_steps"],
                new["line_search"], new["planned_units"]) == REFINE_PLANS[name]
        assert (emb2.epochs, emb2.samples_per_epoch, ref.steps, len(ref.search)) == \
            REFINE_PLANS[name][:4]
        assert new["planned_units"] == (new["epochs"] * new["samples_per_epoch"] + 1 + used(
            ref.steps * (1 + len(ref.search)), ref.steps)) <= budget.units
        assert ref.gamma * ref.steps == pytest.approx(TABLE5[task].gamma * n_steps(TABLE5[task]))
        assert emb2.signal == 1e-6  # no signal, no step
        if name == "standard":
            assert (emb2.epochs, emb2.samples_per_epoch) == (emb.epochs, emb.samples_per_epoch)


def test_gradient_iterations_of_tiny_budgets():
    assert [gradient_iterations(u) for u in (0, 1, 4, 5, 8, 9)] == [0, 0, 0, 1, 1, 2]


def test_a_ray_cluster_without_live_nodes_is_an_error_not_a_hang(monkeypatch):
    """A raylet that dies leaves ``ray.wait`` waiting forever on its tasks: the loop polls,
    and stops with one error once no node is alive. Ray itself is replaced by a stand-in that
    reports a dead cluster (killing a real raylet is not reproducible)."""
    from dbtool.compare import executors

    class DeadCluster:
        cancelled: list = []
        shut = False

        def remote(self, **_):
            return lambda fn: type("R", (), {"remote": staticmethod(lambda spec: spec.task)})

        def wait(self, refs, num_returns, timeout):
            assert timeout is not None  # never an unbounded wait
            return [], refs

        def nodes(self):
            return [{"Alive": False}]

        def cancel(self, ref, force):
            self.cancelled.append(ref)

        def shutdown(self):
            DeadCluster.shut = True

    dead = DeadCluster()
    monkeypatch.setattr(executors, "connect_ray", lambda workers, address: dead)
    specs = [type("S", (), {"threads": 1, "task": t})() for t in ("crawling", "gripping")]
    with pytest.raises(executors.ExecutorError, match="no live node left \\(2 cells"):
        list(executors._ray(specs, 2, None, poll_s=0.01))
    assert sorted(dead.cancelled) == ["crawling", "gripping"] and DeadCluster.shut


def test_a_private_ray_instance_runs_cells_at_the_callers_priority():
    """Ray lowers its workers to nice 15 by default: beside another busy process of the same
    session (a second pytest worker, a notebook) its cells would wait. A private instance keeps
    the caller's priority, like the local executor."""
    code = ("import os\n"
            "from dbtool.compare.executors import connect_ray\n"
            "ray = connect_ray(1, None)\n"
            "print(os.nice(0), ray.get(ray.remote(lambda: os.nice(0)).remote()))\n"
            "ray.shutdown()\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    caller, worker = res.stdout.split()[-2:]
    assert worker == caller
