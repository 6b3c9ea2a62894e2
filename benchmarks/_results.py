"""Shared tail of the benchmark scripts: the JSON result file with its provenance."""

from __future__ import annotations

import json
from pathlib import Path

from dbtool.atomic import atomic_write_text
from dbtool.provenance import provenance


def write_result(result: dict, out: Path | None, default: Path, quick: bool, config: dict,
                 made: dict | None = None) -> Path:
    """Write ``result`` atomically to ``out``, or to ``default`` (``NAME-quick.json`` next to
    it for a quick run), after its provenance (commit, dirty flag, hash of the resolved
    ``config`` and the config, time stamp, machine: :func:`dbtool.provenance.provenance`);
    print and return the path. ``made``: that provenance taken before the script wrote its
    other outputs (which would otherwise mark the checkout dirty)."""
    path = out or (default.with_name(f"{default.stem}-quick.json") if quick else default)
    full = {**(made or provenance(config)), **result}
    atomic_write_text(path, json.dumps(full, indent=2, allow_nan=True))
    print(f"wrote {path}")
    return path
