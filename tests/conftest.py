"""Shared fixtures: one Taichi runtime (CPU, float32) for the whole session.

Kernels take ndarrays, so they compile once per precision and are shared by every test;
the gradient checks switch to float64 for their module and back afterwards.
"""

import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(autouse=True, scope="module")
def taichi_f32(request):
    from dbtool.sim import runtime

    if getattr(request.module, "PRECISION", "f32") == "f32":
        runtime.init("cpu", "f32")
    yield
