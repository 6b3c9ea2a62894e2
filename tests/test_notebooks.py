"""Cheap checks on the paper-figure notebooks; .ci/run executes them (not pytest)."""

import ast
import importlib.util
from pathlib import Path

import manifold3d as m3
import pytest

from dbtool.codesign.config import preset
from dbtool.sim.tasks import TASKS

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("build_notebooks", ROOT / "docs/build_notebooks.py")
build_notebooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(build_notebooks)

SOURCES = build_notebooks.notebook_sources()


def test_there_are_notebooks():
    assert SOURCES, "notebooks/ holds no jupytext notebook (*.py)"


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.stem)
def test_pair_in_sync(source):
    assert build_notebooks.pairing_problems(source) == []


# What DBTOOL_QUICK changes in each notebook, as notebooks/README.md states it:
# (expression evaluated after the notebook's quick-mode code, value with DBTOOL_QUICK=1, unset).
QUICK_SETTINGS = {
    "fig03_tasks": [("STEPS", 30, 100)],
    "fig04_embedding_optimisation": [
        ("N_STEPS", 20, 100), ("RUN", ("crawling", "gripping"), tuple(TASKS)),
        ("settings('crawling').epochs", 2, 4),
        ("settings('crawling').samples_per_epoch", 4, 12),
        ("settings('crawling').sample_steps", 16, 32)],
    "fig05_motion_montage": [
        ("SIZES", {"epochs": 1, "samples_per_epoch": 4, "sample_steps": 16, "refine": 5,
                   "n_steps": 10}, {}), ("UPSAMPLE", False, True),
        ("RUN", ("crawling", "gripping"), tuple(TASKS))],
    "fig08_robotizing": [("len(FAMILIES)", 2, 3), ("STEPS", 10, 100), ("ITERS", 2, 5)],
    "fig11_diffusion_process": [("N", 1, 2), ("STEPS", 32, 64), ("len(US)", 4, 6)],
    "fig13_text_feedback": [
        ("N_STEPS", 10, 100), ("SAMPLE_STEPS", 16, 32), ("cod.t_max", 100, 400),
        ("[p[0] for p in PAIRS]", ["crawling", "box"],
         ["balancing", "crawling", "hurdling", "box"])],
    "fig14_fabrication": [("EXPORT_AFRESH", False, True),
                          ("finger.bounding_box()[4] - finger.bounding_box()[1]", 20.0, 60.0)],
    "fig16_sim_vs_real": [("TENDONS", ("flexion",), ("flexion", "extension")),
                          ("FIT", ("gain",), ("gain", "stiffness_scale", "friction_mm")),
                          ("MAX_EVALS", 3, 20)],
    "fig12_baselines": [("TASKS", ("crawling",), ("crawling", "gripping", "hurdling")),
                        ("BUDGET", "smoke", "smoke")],
    "table_main": [("TASKS", ("gripping",),
                    ("balancing", "landing", "crawling", "hurdling", "gripping", "box")),
                   ("SEEDS", (0,), (0, 1)), ("BUDGET", "smoke", "smoke")],
}


def _context(stem: str) -> dict:
    """Values the quick-mode code of a notebook works on (made by earlier, expensive cells)."""
    if stem == "fig13_text_feedback":
        return {"cod": preset("quick", "crawling")[1]}
    if stem == "fig14_fabrication":  # a stand-in finger, 60 mm tall
        finger = m3.Manifold.cube([30.0, 60.0, 20.0])
        box = finger.bounding_box()
        return {"finger": finger, "lo": list(box[:3]), "hi": list(box[3:])}
    return {}


def _quick_code(source: Path) -> ast.Module:
    """The notebook's imports, then (in order) every top-level assignment or function that reads
    QUICK and every ``if QUICK`` block at any depth: its settings, without running its work."""
    tree = ast.parse(source.read_text())

    def reads(node: ast.AST) -> bool:
        return any(isinstance(n, ast.Name) and n.id == "QUICK" for n in ast.walk(node))

    body = [n for n in tree.body if isinstance(n, ast.Import | ast.ImportFrom)]
    for node in tree.body:
        if isinstance(node, ast.Assign | ast.FunctionDef) and reads(node):
            body.append(node)
        elif not isinstance(node, ast.Import | ast.ImportFrom):
            body += [n for n in ast.walk(node) if isinstance(n, ast.If) and reads(n.test)]
    return ast.Module(body=body, type_ignores=[])


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.stem)
def test_honours_quick_mode(source, monkeypatch):
    """DBTOOL_QUICK=1 gives the small settings notebooks/README.md lists; unset, the larger
    ones (only the settings are evaluated, not the notebook's work)."""
    assert source.stem in QUICK_SETTINGS, f"{source.name}: add its quick settings here"
    code = compile(_quick_code(source), str(source), "exec")
    values = {}
    for mode in ("1", None):
        if mode is None:
            monkeypatch.delenv("DBTOOL_QUICK", raising=False)
        else:
            monkeypatch.setenv("DBTOOL_QUICK", mode)
        ns = _context(source.stem)
        exec(code, ns)
        assert ns["QUICK"] is (mode == "1")
        values[mode] = [eval(expr, ns) for expr, *_ in QUICK_SETTINGS[source.stem]]
    for (expr, quick, full), q, f in zip(QUICK_SETTINGS[source.stem], values["1"], values[None],
                                         strict=True):
        assert (q, f) == (quick, full), f"{source.name}: {expr} is {q} quick, {f} unset"
