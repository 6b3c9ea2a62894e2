"""Which float format the prior computes in on this machine (docs/prior.md, "Speed").

bfloat16 autocast pays only where the CPU multiplies bfloat16 natively (AVX512-BF16 or AMX):
there training steps were 2.7x faster than float32. Without those units PyTorch emulates it,
and a 1,024 x 1,024 matmul measured 0.8 GFLOPS in bfloat16 against 85 GFLOPS in float32 on
an AVX2-only 2-core CPU, so sampling took 3x longer than in float32 instead of less. The
default is therefore chosen per machine; ``DBTOOL_BF16=1`` or ``0`` overrides it.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

from dbtool.errors import InputError

NATIVE_FLAGS = ("avx512_bf16", "amx_bf16")  # /proc/cpuinfo flags of native bfloat16 units


def _cpuinfo_field(names: tuple[str, ...], cpuinfo: str | None) -> str | None:
    if cpuinfo is None:
        path = Path("/proc/cpuinfo")
        cpuinfo = path.read_text(errors="replace") if path.is_file() else ""
    for line in cpuinfo.splitlines():
        if line.split(":", 1)[0].strip() in names:
            return line.split(":", 1)[1].strip()
    return None


def cpu_flags(cpuinfo: str | None = None) -> set[str]:
    """The CPU feature flags Linux reports (empty where ``/proc/cpuinfo`` does not exist)."""
    return set((_cpuinfo_field(("flags", "Features"), cpuinfo) or "").split())


def cpu_model(cpuinfo: str | None = None) -> str | None:
    """The CPU's model name as Linux reports it (None where it does not)."""
    return _cpuinfo_field(("model name",), cpuinfo)


@functools.lru_cache(maxsize=1)
def native_bf16() -> bool:
    """Whether bfloat16 autocast is the faster choice here: ``DBTOOL_BF16`` when set, else
    whether the CPU has a native bfloat16 unit."""
    env = os.environ.get("DBTOOL_BF16", "").strip().lower()
    if env:
        if env not in ("0", "1", "true", "false", "yes", "no"):
            raise InputError(f"DBTOOL_BF16={env!r}: use 1 or 0")
        return env in ("1", "true", "yes")
    return bool(set(NATIVE_FLAGS) & cpu_flags())


def use_bf16(device_type: str, setting: bool | None = None) -> bool:
    """Autocast to bfloat16 on ``device_type``? ``setting`` when given; else on a CPU
    :func:`native_bf16`, on an accelerator yes."""
    if setting is not None:
        return setting
    return native_bf16() if device_type == "cpu" else True
