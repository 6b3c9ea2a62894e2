"""Shared fixtures: one Taichi runtime (CPU, float32) for the whole session.

Kernels take ndarrays, so they compile once per precision and are shared by every test;
the gradient checks switch to float64 for their module and back afterwards.
"""

import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(autouse=True, scope="module")
def taichi_precision(request):
    """The module's ``PRECISION`` (default f32) for its tests, f32 again afterwards."""
    from dbtool.sim import runtime

    runtime.init("cpu", getattr(request.module, "PRECISION", "f32"))
    yield
    runtime.init("cpu", "f32")
