"""No command deletes or rewrites what it did not create (docs/safety.md): exports never
replace their input or a user's files, run folders are claimed and locked, an interrupted run
keeps its promise, and only finished exports are shown."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from bad_input import assert_refused, snapshot
from cli_inprocess import run_cli

from dbtool.design import Design
from dbtool.export.complete import MARKER, ExportFolder, check_complete, mark_complete
from dbtool.lock import FolderLock, FolderLockedError
from dbtool.robotize.actuators import reference_robot
from dbtool.runs import LOCK_NAME, RunDir, RunFolder, RunFolderError, folder_kind
from dbtool.sim.tasks import get_task

REFERENCE = Path(__file__).resolve().parents[1] / "exports" / "gripping-seed0"
CLI = [sys.executable, "-m", "dbtool.cli"]


def _copy_reference(tmp: Path) -> Path:
    dest = tmp / "exports" / "gripping-seed0"
    shutil.copytree(REFERENCE, dest)
    return dest


def _holder(folder: Path, kind: str = "simulate") -> subprocess.Popen:
    """A process that claims ``folder`` as a ``kind`` run and holds it until killed."""
    code = ("import sys, time; from dbtool.runs import RunDir; "
            f"r = RunDir({str(folder)!r}, {{'command': {kind!r}}}, 0, 'cpu', kind={kind!r}); "
            "print('held', flush=True); time.sleep(600)")
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "held"
    return p


# ------------------------------------------------------------------ exports
def test_export_never_replaces_the_folder_that_holds_its_input(tmp_path):
    """The documented ``--design FILE`` form given the reference design, from the repository
    root: the export would go to exports/gripping-seed0, which holds the design."""
    _copy_reference(tmp_path)
    before = snapshot(tmp_path)
    out = run_cli("export", "--design", "exports/gripping-seed0/design.npz", "--stl",
                  cwd=tmp_path)
    assert_refused(out, tmp_path, before, "folder that holds its input", "--out")


def test_export_never_deletes_a_users_files(tmp_path):
    """An earlier export with a user's file beside it, or a user's folder of the same name,
    is refused; the reference export's own design and log count as the user's."""
    ref = _copy_reference(tmp_path)
    design = tmp_path / "gripping-seed0.npz"
    shutil.copy(ref / "design.npz", design)
    before = snapshot(tmp_path)
    out = run_cli("export", "--design", str(design), "--out", "exports", cwd=tmp_path)
    assert_refused(out, tmp_path, before, "files the export did not write", "design.npz")
    (tmp_path / "mine" / "gripping-seed0").mkdir(parents=True)
    (tmp_path / "mine" / "gripping-seed0" / "notes.txt").write_text("my notes")
    before = snapshot(tmp_path)
    out = run_cli("export", "--design", str(design), "--out", "mine", cwd=tmp_path)
    assert_refused(out, tmp_path, before, "not a finished dbtool export")


def test_export_folder_is_locked_and_partials_of_killed_exports_are_cleaned(tmp_path):
    task = get_task("crawling")
    design = Design("crawling", reference_robot(task, "box"), task.controller()).save(
        tmp_path / "d.npz")
    dead = tmp_path / "out" / ".d.partial-99999999-abc"  # a killed export's temp folder
    dead.mkdir(parents=True)
    (dead / "body.stl").write_text("half")
    with ExportFolder(design, tmp_path / "out" / "d") as folder:
        assert not dead.exists() and any("interrupted export" in n for n in folder.notes)
        with pytest.raises(FolderLockedError, match=f"process {os.getpid()}"):
            ExportFolder(design, tmp_path / "out" / "d")
    assert not (tmp_path / "out" / ".d.lock").exists()
    ExportFolder(design, tmp_path / "out" / "d").lock.release()  # free again


def test_report_and_view_take_only_a_finished_export(tmp_path):
    ref = _copy_reference(tmp_path)
    check_complete(ref)  # the committed export carries its marker
    (ref / MARKER).unlink()  # an export killed before its marker
    before = snapshot(tmp_path)
    for cmd in ("report", "view"):
        out = run_cli(cmd, str(ref), cwd=tmp_path)
        assert_refused(out, tmp_path, before, "not a finished export")
    mark_complete(ref)
    (ref / "tendons.json").unlink()  # a listed file gone
    before = snapshot(tmp_path)
    out = run_cli("report", str(ref), cwd=tmp_path)
    assert_refused(out, tmp_path, before, "incomplete export", "tendons.json")


def test_the_reference_export_marker_lists_its_own_files_only():
    marker = json.loads((REFERENCE / MARKER).read_text())
    assert "design.npz" not in marker["files"]  # the design was copied in by hand
    assert all((REFERENCE / f).is_file() for f in marker["files"])


# ------------------------------------------------------------------ run folders
def test_run_folders_of_another_kind_or_a_users_are_refused(tmp_path):
    task = get_task("crawling")
    Design("crawling", reference_robot(task, "box"), task.controller()).save(tmp_path / "d.npz")
    sim = tmp_path / "sim"
    RunDir(sim, {"command": "simulate"}, 0, "cpu", kind="simulate").close()
    (sim / "metrics.jsonl").write_text('{"metric": 1}\n')
    comparison = tmp_path / "cmp"
    comparison.mkdir()
    (comparison / "compare.json").write_text("{}")
    (comparison / "manifest.json").write_text("{}")
    user = tmp_path / "user"
    user.mkdir()
    (user / "thesis.tex").write_text("x")
    assert folder_kind(sim) == "simulate" and folder_kind(comparison) == "compare"
    assert folder_kind(user) is None
    cases = [
        (("design", "crawling", "--run-dir", "sim"), "holds a simulate run"),
        (("design", "crawling", "--run-dir", "cmp"), "holds a compare run"),
        (("design", "crawling", "--run-dir", "user"), "holds no dbtool run"),
        (("design", "crawling", "--run-dir", "d.npz"), "is a file"),
        (("design", "crawling", "--method", "particle", "--run-dir", "sim"), "simulate run"),
        (("simulate", "crawling", "--out", "cmp"), "holds a compare run"),
        (("simulate", "crawling", "--out", "user"), "holds no dbtool run"),
        (("compare", "--tasks", "crawling", "--out", "sim"), "not empty"),
        (("generate", "a star", "-o", "user"), "holds no dbtool run"),
    ]
    for args, words in cases:
        before = snapshot(tmp_path)
        assert_refused(run_cli(*args, cwd=tmp_path), tmp_path, before, words)


def test_a_run_of_the_same_kind_is_rerun_in_place(tmp_path):
    """``simulate --out`` on its own earlier run: its files are replaced, the log starts
    afresh (no rows of the earlier run), and the folder is unlocked afterwards."""
    for _ in range(2):
        out = run_cli("simulate", "crawling", "--steps", "2", "--no-gif", "--out", "r",
                      cwd=tmp_path)
        assert out.returncode == 0, out.stderr
    rows = (tmp_path / "r" / "metrics.jsonl").read_text().splitlines()
    assert len(rows) == 1 and not (tmp_path / "r" / LOCK_NAME).exists()


def test_a_folder_being_written_is_locked_and_a_crashed_holder_is_detected(tmp_path):
    folder = tmp_path / "run"
    holder = _holder(folder)
    try:
        before = snapshot(tmp_path)
        out = run_cli("simulate", "crawling", "--steps", "2", "--out", "run", cwd=tmp_path)
        assert_refused(out, tmp_path, before, "being written by", f"process {holder.pid}")
        with pytest.raises(FolderLockedError, match=str(holder.pid)):
            FolderLock(folder / LOCK_NAME, folder).acquire()
    finally:
        holder.kill()  # a crash: no clean-up runs
        holder.wait()
    assert (folder / LOCK_NAME).exists()  # the dead holder's lock file is left behind ...
    lock = FolderLock(folder / LOCK_NAME, folder).acquire()  # ... and taken over
    assert lock.stale is not None and lock.stale["pid"] == holder.pid
    lock.release()
    out = run_cli("simulate", "crawling", "--steps", "2", "--no-gif", "--out", "run",
                  cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert not (folder / LOCK_NAME).exists()


def test_two_claims_of_one_new_folder_exclude_each_other(tmp_path):
    first = RunFolder(tmp_path / "new", "design")
    with pytest.raises(FolderLockedError):
        RunFolder(tmp_path / "new", "design")
    first.abandon()  # nothing saved: the folder goes
    assert not (tmp_path / "new").exists()
    (tmp_path / "f").write_text("y")
    with pytest.raises(RunFolderError, match="is a file"):
        RunFolder(tmp_path / "f", "design")


def test_a_failure_after_the_folder_was_made_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError), RunDir(tmp_path / "a" / "b", {}, 0, "cpu",
                                             kind="simulate"):
        raise RuntimeError("the simulation diverged")
    assert not (tmp_path / "a").exists()


# ------------------------------------------------------------------ interruptions
def test_ctrl_c_before_the_first_checkpoint_leaves_nothing_and_says_so(tmp_path):
    """Ctrl-C during the first embedding epoch: no resume hint that cannot work, the
    folder it made is gone, and the command it prints starts the run again."""
    p = subprocess.Popen([*CLI, "design", "crawling", "--steps", "4", "--run-dir", "r"],
                         cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    line = ""
    deadline = time.monotonic() + 300
    while "run directory" not in line and time.monotonic() < deadline:
        line = p.stdout.readline()
        assert line or p.poll() is None, p.stderr.read()
    assert (tmp_path / "r" / "config.json").is_file()
    assert not (tmp_path / "r" / "checkpoint.pt").exists()
    p.send_signal(signal.SIGINT)
    _out, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    assert "nothing to resume" in err and "--resume" not in err, err
    assert "start again with: dbtool design crawling --steps 4 --run-dir r" in err, err
    assert not (tmp_path / "r").exists()


def test_errors_name_the_file_not_its_temporary_name(tmp_path):
    """A failure while a file or folder is written names the final path the user asked for,
    never the hidden temporary one."""
    from dbtool.atomic import atomic_folder, atomic_write
    from dbtool.errors import InputError, PathError

    def full(tmp):
        raise OSError(28, "No space left on device", tmp)

    with pytest.raises(PathError) as info:
        atomic_write(tmp_path / "design.npz", full)
    assert str(info.value) == f"cannot write {tmp_path / 'design.npz'}: No space left on device"
    with pytest.raises(InputError) as info, atomic_folder(tmp_path / "export") as tmp:
        raise InputError(f"{tmp / 'report.json'} is not valid")
    assert str(info.value) == f"{tmp_path / 'export' / 'report.json'} is not valid"
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no temporary file or folder


def test_report_refuses_a_run_another_process_writes(tmp_path):
    folder = tmp_path / "run"
    holder = _holder(folder, "design")
    try:
        task = get_task("crawling")
        Design("crawling", reference_robot(task, "box"), task.controller()).save(
            folder / "design.npz")
        before = snapshot(tmp_path)
        out = run_cli("report", "run", cwd=tmp_path)
        assert_refused(out, tmp_path, before, "being written by", f"process {holder.pid}")
    finally:
        holder.kill()
        holder.wait()
