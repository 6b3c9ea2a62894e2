"""Provenance of results: config hash, commit and dirty flag, and the caches keyed on both."""

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from _codesign_experiments import Cache

from dbtool.codesign.config import preset
from dbtool.provenance import commit_tag, config_hash, git_commit, provenance
from dbtool.runs import manifest

RESULTS = Path(__file__).parents[1] / "benchmarks" / "results"


def test_config_hash_is_stable_and_changes_with_any_setting():
    emb, cod = preset("quick", "crawling")
    cfg = {"task": "crawling", "seed": 0, "embedding": emb, "codesign": cod, "steps": (1, 2)}
    same = {"steps": [1, 2], "codesign": cod, "seed": 0, "embedding": emb, "task": "crawling"}
    h = config_hash(cfg)
    assert len(h) == 16 and int(h, 16) >= 0
    assert config_hash(same) == h  # key order and tuple/list do not matter
    # a fresh process gives the same hash (no dependence on hash seeds or ids)
    code = ("from dbtool.codesign.config import preset; from dbtool.provenance import "
            "config_hash; e, c = preset('quick', 'crawling'); print(config_hash({'task': "
            "'crawling', 'seed': 0, 'embedding': e, 'codesign': c, 'steps': (1, 2)}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.stdout.strip() == h, out.stderr[-400:]
    for changed in ({**cfg, "seed": 1}, {**cfg, "codesign": replace(cod, kappa=0.0)},
                    {**cfg, "embedding": replace(emb, lr=0.5)}, {**cfg, "extra": None}):
        assert config_hash(changed) != h
    assert config_hash(preset("paper", "crawling")) != config_hash(preset("quick", "crawling"))


def _git(root: Path, *args: str) -> str:
    return subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args],
                          cwd=root, capture_output=True, text=True, check=True).stdout.strip()


def test_commit_and_dirty_flag_are_recorded(tmp_path):
    assert git_commit(tmp_path) == {"sha": None, "dirty": None}  # not a checkout
    _git(tmp_path, "init", "-q")
    (tmp_path / "a.py").write_text("x = 1\n")
    _git(tmp_path, "add", "a.py")
    _git(tmp_path, "commit", "-qm", "one")
    sha = _git(tmp_path, "rev-parse", "HEAD")
    assert git_commit(tmp_path) == {"sha": sha, "dirty": False}
    (tmp_path / "new.txt").write_text("untracked files do not count")
    assert git_commit(tmp_path)["dirty"] is False
    (tmp_path / "a.py").write_text("x = 2\n")
    commit = git_commit(tmp_path)
    assert commit == {"sha": sha, "dirty": True}
    assert commit_tag(commit) == sha[:12] + "-dirty"
    prov = provenance({"b": 1, "a": [1, 2]}, commit)
    assert prov["commit"] == sha and prov["dirty"] is True
    assert prov["config_hash"] == config_hash({"a": [1, 2], "b": 1})
    assert prov["config"] == {"a": [1, 2], "b": 1}
    assert {"hostname", "platform", "cpus", "python", "torch"} <= set(prov["machine"])
    assert prov["created"][:2] == "20"


def test_run_manifest_records_the_checkout_and_the_config():
    cfg = {"command": "design", "seed": 3}
    m = manifest(3, "cpu", cfg)
    here = git_commit()
    assert m["commit"] == here["sha"] and m["dirty"] == here["dirty"]
    assert m["config_hash"] == config_hash(cfg) and "config" not in m
    assert m["seed"] == 3 and m["device"] == "cpu"


def test_cache_is_keyed_on_config_and_commit(tmp_path):
    a = {"sha": "a" * 40, "dirty": False}
    calls = []

    def work():
        calls.append(1)
        return {"metric": 0.5}

    cache = Cache(tmp_path, a, log=None)
    out = cache.get("run-crawling-0", {"seed": 0}, work)
    assert out["metric"] == 0.5 and out["commit"] == "a" * 40 and out["seconds"] >= 0
    assert cache.get("run-crawling-0", {"seed": 0}, work)["metric"] == 0.5
    assert len(calls) == 1  # the second call was served from the cache
    stored = json.loads(cache.path("run-crawling-0", {"seed": 0}).read_text())
    assert stored["config_hash"] == config_hash({"seed": 0})
    assert cache.load("run-crawling-0", {"seed": 1}) is None  # another config
    assert Cache(tmp_path, {"sha": "b" * 40, "dirty": False}).load(
        "run-crawling-0", {"seed": 0}) is None  # another commit
    assert Cache(tmp_path, {**a, "dirty": True}).load("run-crawling-0", {"seed": 0}) is None


@pytest.mark.parametrize("path", sorted(p for p in RESULTS.glob("*.json")),
                         ids=lambda p: p.name)
def test_every_result_carries_its_provenance(path):
    """Results from before provenance live in ``benchmarks/results/legacy/`` (its README)."""
    res = json.loads(path.read_text())
    assert len(res["commit"]) == 40 and isinstance(res["dirty"], bool)
    assert res["config_hash"] == config_hash(res["config"])
    assert {"hostname", "platform", "cpus"} <= set(res["machine"]) and res["created"]
