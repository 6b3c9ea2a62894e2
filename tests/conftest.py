"""Shared fixtures: one Taichi runtime (CPU, float32) for the whole session.

Kernels take ndarrays, so they compile once per precision and are shared by every test;
the gradient checks switch to float64 for their module and back afterwards. Under
pytest-xdist (``pytest -n 2``, as CI runs) each worker process has its own runtime.
"""

import os
import sys
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# benchmark support code that tests exercise (``_codesign_experiments``), last on the path so
# that the benchmarks' scripts never shadow an installed module
sys.path.append(str(Path(__file__).resolve().parents[1] / "benchmarks"))
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
    # pytest-xdist workers share the cores: one Taichi and one torch thread each (set before
    # either is imported; subprocesses the tests start inherit it).
    for _var in ("DBTOOL_THREADS", "OMP_NUM_THREADS"):
        os.environ.setdefault(_var, "1")


# Files whose tests pytest-xdist may spread over the workers one by one; every other file's
# tests stay on one worker together (``--dist loadgroup``), so its module fixtures and caches
# are built once.
SPREAD = {"test_fuzz"}


def pytest_itemcollected(item):
    """Mark each test with its file's group as it is collected: pytest-xdist turns the marks
    into the node ids it schedules by in its own ``pytest_collection_modifyitems``, which ran
    before one here (the marks came too late and every file was spread over both workers)."""
    name = item.module.__name__.rsplit(".", 1)[-1]
    if name not in SPREAD:
        item.add_marker(pytest.mark.xdist_group(name))


@pytest.fixture(autouse=True, scope="module")
def taichi_precision(request):
    """The module's ``PRECISION`` (default f32) for its tests, f32 again afterwards."""
    from dbtool.sim import runtime

    runtime.init("cpu", getattr(request.module, "PRECISION", "f32"))
    yield
    runtime.init("cpu", "f32")


def pytest_collection_modifyitems(config, items):
    """Tests marked ``slow`` (tens of minutes on a laptop CPU) run only with ``DBTOOL_SLOW=1``
    (``DBTOOL_SLOW=1 pytest -m slow``); everywhere else they are reported as skipped."""
    if os.environ.get("DBTOOL_SLOW") == "1":
        return
    skip = pytest.mark.skip(reason="slow: set DBTOOL_SLOW=1 to run")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
