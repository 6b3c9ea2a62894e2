"""The prior's float format per machine (dbtool.precision)."""

from __future__ import annotations

import pytest

from dbtool import precision

AMX = "processor\t: 0\nflags\t\t: fpu sse avx2 avx512f avx512_bf16 amx_bf16 amx_tile\n"
AVX2 = "processor\t: 0\nflags\t\t: fpu sse sse2 avx avx2 fma\n"
ARM = "processor\t: 0\nFeatures\t: fp asimd bf16 i8mm\n"


def test_cpu_flags_are_read_from_cpuinfo():
    assert "amx_bf16" in precision.cpu_flags(AMX)
    assert "avx2" in precision.cpu_flags(AVX2) and "avx512_bf16" not in precision.cpu_flags(AVX2)
    assert "asimd" in precision.cpu_flags(ARM)
    assert precision.cpu_flags("") == set()


@pytest.mark.parametrize(("cpuinfo", "native"),
                         [(AMX, True), (AVX2, False), (ARM, False), ("", False)])
def test_bf16_only_where_native(monkeypatch, cpuinfo, native):
    monkeypatch.delenv("DBTOOL_BF16", raising=False)
    flags = precision.cpu_flags(cpuinfo)
    monkeypatch.setattr(precision, "cpu_flags", lambda: flags)
    precision.native_bf16.cache_clear()
    try:
        assert precision.native_bf16() is native
        assert precision.use_bf16("cpu") is native
        assert precision.use_bf16("cpu", True) is True and precision.use_bf16("cpu", False) is False
        assert precision.use_bf16("cuda") is True
    finally:
        precision.native_bf16.cache_clear()


def test_environment_overrides(monkeypatch):
    for value, expected in (("1", True), ("0", False)):
        monkeypatch.setenv("DBTOOL_BF16", value)
        precision.native_bf16.cache_clear()
        assert precision.native_bf16() is expected
    monkeypatch.setenv("DBTOOL_BF16", "fast")
    precision.native_bf16.cache_clear()
    with pytest.raises(ValueError, match="DBTOOL_BF16"):
        precision.native_bf16()
    precision.native_bf16.cache_clear()


def test_results_record_the_cpu_and_its_precision():
    from dbtool.provenance import machine

    assert precision.cpu_model("model name\t: AMD EPYC\nflags\t: avx2\n") == "AMD EPYC"
    assert precision.cpu_model("") is None
    m = machine()
    assert m["bf16_native"] is precision.native_bf16() and "cpu" in m
