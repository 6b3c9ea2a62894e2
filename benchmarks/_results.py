"""Shared tail of the benchmark scripts: the machine description and the JSON result file."""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

from dbtool.atomic import atomic_write_text


def machine() -> dict:
    import torch

    return {"platform": platform.platform(), "processor": platform.processor(),
            "cpus": os.cpu_count(), "torch": torch.__version__}


def write_result(result: dict, out: Path | None, default: Path, quick: bool) -> Path:
    """Write ``result`` (plus machine and time stamp) atomically to ``out``, or to ``default``
    (``NAME-quick.json`` next to it for a quick run); print and return the path."""
    path = out or (default.with_name(f"{default.stem}-quick.json") if quick else default)
    full = {"machine": machine(), **result, "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    atomic_write_text(path, json.dumps(full, indent=2))
    print(f"wrote {path}")
    return path
