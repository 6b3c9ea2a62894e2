"""The shipped prior: prompt fidelity on a subset of families, upsampler, `dbtool generate`."""

import os
import subprocess
import sys

import numpy as np
import pytest
import torch
from cli_inprocess import run_cli

from dbtool.pointcloud import load_ply
from dbtool.prior.sampling.pipeline import BASE_WEIGHTS, UPSAMPLER_WEIGHTS, CheckpointError, Prior
from dbtool.prior.training.evaluate import evaluate
from dbtool.prior.training.metrics import chamfer_matrix

SUBSET = ["ball", "star", "table", "ring", "bar", "finger"]


@pytest.fixture(scope="module")
def prior():
    return Prior.load()


def test_weights_ship_with_the_package():
    assert BASE_WEIGHTS.is_file() and UPSAMPLER_WEIGHTS.is_file()
    size = BASE_WEIGHTS.stat().st_size + UPSAMPLER_WEIGHTS.stat().st_size
    assert size < 40e6


def test_prompt_fidelity_on_a_subset(prior):
    """1-NN family accuracy (Chamfer, held-out references) on six families, 8 samples each,
    against 8 references of every family (the card uses 32: building them is most of the
    time)."""
    res = evaluate(prior, SUBSET, samples=8, steps=32, paraphrases=False, interpolate=False,
                   log=None, heldout_per_family=4, metric_points=256, reference_per_family=8)
    # the references cover every family, so any confusion counts as a mistake
    accs = {f: r["accuracy"] for f, r in res["families"].items()}
    assert res["ceiling"] > 0.95
    assert res["accuracy"] >= 0.8, accs
    assert min(accs.values()) >= 0.5, accs
    for fam, r in res["families"].items():  # no collapse onto one shape
        assert r["spread_ratio"] > 0.2, (fam, r)


def test_upsampler_densifies_the_coarse_cloud(prior):
    coarse = prior.sample("a table", n=2, steps=16, seed=0).clouds
    fine = prior.upsample(coarse, steps=16, seed=0)
    assert fine.shape == (2, 4096, 3)
    assert np.array_equal(fine[:, :1024], coarse)  # the coarse points are kept
    new = torch.from_numpy(fine[:, 1024:].astype(np.float32))
    c = torch.from_numpy(coarse.astype(np.float32))
    near = torch.diagonal(chamfer_matrix(new, c))
    rng = np.random.default_rng(0)
    noise = torch.from_numpy(rng.uniform(-0.5, 0.5, (2, 3072, 3)).astype(np.float32))
    assert torch.all(near < 0.1 * torch.diagonal(chamfer_matrix(noise, c)))


def test_wrong_or_missing_weights_are_named(tmp_path):
    with pytest.raises(CheckpointError, match="not the base model"):
        Prior.load(UPSAMPLER_WEIGHTS)
    with pytest.raises(CheckpointError, match="not found"):
        Prior.load(upsampler=tmp_path / "none.pt")


def _generate(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "dbtool.cli", "generate", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=600)


def test_generate_writes_clouds_npz_and_grid(tmp_path):
    out = _generate("a star", "-n", "2", "--sample-steps", "8", "--upsample", "-o",
                    str(tmp_path / "g"))
    assert out.returncode == 0, out.stderr
    g = tmp_path / "g"
    for name in ("a-star-0.ply", "a-star-1.ply", "samples.npz", "grid.png", "generate.json"):
        assert (g / name).stat().st_size > 0, name
    pts = load_ply(g / "a-star-0.ply")
    assert pts.shape == (4096, 3) and np.abs(pts).max() <= 0.5 + 1e-5
    d = np.load(g / "samples.npz")
    assert d["coarse"].shape == (2, 1024, 3) and d["fine"].shape == (2, 4096, 3)
    assert np.array_equal(d["fine"][0], pts)
    umask = os.umask(0)
    os.umask(umask)
    for f in g.iterdir():  # ordinary file permissions, not the temp file's 0600
        assert f.stat().st_mode & 0o777 == 0o666 & ~umask, f


@pytest.mark.parametrize("args, message", [
    (("", "-o", "OUT"), "prompt is empty"),
    (("a star", "--guidance", "1e9", "-o", "OUT"), "guidance scale"),
    (("a star", "--base", "missing.pt", "-o", "OUT"), "checkpoint not found"),
    (("a star", "--upsample", "--upsampler", "none.pt", "-o", "OUT"), "checkpoint not found"),
])
def test_generate_bad_input_is_one_line(tmp_path, args, message):
    args = [str(tmp_path / "o") if a == "OUT" else a for a in args]
    out = run_cli("generate", *args, cwd=tmp_path)
    assert out.returncode != 0
    errors = [line for line in out.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], out.stderr
    assert "Traceback" not in out.stderr
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_weights_folders_are_versioned():
    from dbtool.prior.sampling.pipeline import DEFAULT_VERSION, weights_dir

    assert weights_dir(1) == BASE_WEIGHTS.parent or DEFAULT_VERSION != 1
    assert (weights_dir(1) / "base.pt").is_file() and (weights_dir(1) / "eval.json").is_file()
    with pytest.raises(CheckpointError, match="no shipped prior version 99; shipped: v1"):
        weights_dir(99)
    with pytest.raises(CheckpointError, match="version 99"):
        Prior.load(version=99)
    assert Prior.load(version=2, with_upsampler=False).corpus == 2
    v3 = Prior.load(version=3)  # version 3 reads token states and reuses version 2's upsampler
    assert (v3.corpus, v3.tokens) == (3, 24) and v3.upsampler is not None


def test_a_version_without_upsampler_says_so(tmp_path, monkeypatch):
    import shutil

    from dbtool.prior.sampling import pipeline

    (tmp_path / "v7").mkdir()
    shutil.copy(pipeline.weights_dir(1) / "base.pt", tmp_path / "v7" / "base.pt")
    shutil.copytree(pipeline.weights_dir(1), tmp_path / "v1")
    monkeypatch.setattr(pipeline, "WEIGHTS_ROOT", tmp_path)
    assert Prior.load(version=7, with_upsampler=False).upsampler is None
    with pytest.raises(CheckpointError, match="prior v7 has no upsampler; load it with"):
        Prior.load(version=7)
    # a version may name an earlier version's upsampler (it reads no text)
    (tmp_path / "v7" / "config.json").write_text('{"upsampler_from": 1}')
    up = Prior.load(version=7).upsampler
    assert up is not None and torch.equal(
        up.out.weight, pipeline.load_model(tmp_path / "v1" / "upsampler.pt")[0].out.weight)
    # and the steps its guidance is limited to (docs/prior.md)
    assert Prior.load(version=7, with_upsampler=False).guidance_interval is None
    (tmp_path / "v7" / "config.json").write_text('{"guidance_interval": [0, 400]}')
    assert Prior.load(version=7, with_upsampler=False).guidance_interval == (0, 400)


@pytest.mark.parametrize("text", ["400", "a:b", "500:100", "-1:10"])
def test_a_bad_guidance_interval_is_one_line(text):
    from dbtool.cli.prior import parse_interval
    from dbtool.errors import InputError

    with pytest.raises(InputError, match="guidance interval"):
        parse_interval(text)
    assert parse_interval("0:400") == (0, 400)


def test_a_far_prompt_names_the_nearest_known_captions():
    from dbtool.prior.sampling.generate import KNOWN, far_prompt_note, nearest_captions

    assert far_prompt_note("a star") is None  # a training caption
    near = nearest_captions("a teapot")
    assert len(near) == 3 and near[0][1] < KNOWN and near[0][1] >= near[2][1]
    note = far_prompt_note("a teapot")
    assert note.startswith("note: 'a teapot' is far") and repr(near[0][0]) in note


def test_generate_with_another_version_notes_that_versions_captions(tmp_path):
    """``--prior 2`` samples version 2 (base and upsampler) and a far prompt's note names
    version 2's captions, not version 1's."""
    from dbtool.prior.sampling.generate import nearest_captions

    near = nearest_captions("a teapot with a long spout", 1, version=2)[0][0]
    assert near not in {c for c, _ in nearest_captions("a teapot with a long spout", 50)}
    out = _generate("a teapot with a long spout", "--prior", "2", "-n", "1", "--sample-steps", "4",
                    "--upsample", "-o", str(tmp_path / "g"))
    assert out.returncode == 0, out.stderr
    assert repr(near) in out.stderr
    assert np.load(tmp_path / "g" / "samples.npz")["fine"].shape == (1, 4096, 3)


def test_an_interrupted_evaluation_resumes_to_the_same_numbers(prior, tmp_path):
    """Every finished piece is kept; a resumed evaluation recomputes only the missing ones and
    gives the numbers of an uninterrupted run; another key is refused."""
    import json

    from dbtool.prior.training.evaluate import Parts, weights_digest

    kw = dict(families=["ball", "bar"], reference_families=["ball", "bar", "ring"], samples=2,
              steps=2, log=None, heldout_per_family=2, metric_points=64,
              reference_per_family=2)
    key = {"weights": weights_digest(prior.base), "samples": 2}
    path = tmp_path / "eval.parts.json"
    full = evaluate(prior, parts=Parts(path, key).get, **kw)
    saved = json.loads(path.read_text())["parts"]
    assert {"ceiling", "family/ball", "family/bar", "paraphrase/a doughnut",
            "interpolation/bar/ring"} <= saved.keys()
    del saved["family/bar"], saved["interpolation/bar/ring"]  # as if it stopped there
    path.write_text(json.dumps({"key": key, "parts": saved}))
    parts = Parts(path, key)
    assert parts.loaded == len(saved)
    resumed = evaluate(prior, parts=parts.get, **kw)
    for k in ("accuracy", "ceiling", "families", "paraphrases", "interpolations"):
        assert resumed[k] == full[k], k
    with pytest.raises(ValueError, match="other settings or weights"):
        Parts(path, {**key, "samples": 3})
