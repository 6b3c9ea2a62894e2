"""Permutation-invariant latent-attention transformers for point-cloud diffusion.

Point-E's models (docs/method.md §1) are transformers over the points: each point is a token (no
positional encoding), the timestep and the condition are extra tokens, the output is epsilon per
point. Full self-attention over 1,024 points costs 2.8-3.9 s per training step on this CPU
(``MODEL_CARD.md``), so dbtool routes attention through a small set of learned
latents (Perceiver IO): the latents read every token (cross-attention), think among themselves
together with the time and condition tokens (self-attention), and every point reads the latents
back. The cost is linear in the number of points and the network is exactly permutation
equivariant: nothing depends on the order of the points.

The upsampler is the same network with a second point set, the coarse cloud: its tokens join
the latents' context and the points' decoder context, so fine points can copy local detail.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import nn

from dbtool.prior.sampling.diffusion import T_TRAIN

# Inference runs the batch in chunks of about this many point tokens: the (tokens x 4 width)
# MLP activations then stay in the CPU's cache. Same numbers; with the fused attention below, a
# forward pass of 120 x 1,024 points took 3.9 s instead of 7.6 s on one AVX2 core.
INFER_TOKENS = 4096


@dataclass
class ModelConfig:
    """Sizes of a :class:`PointDiffusionTransformer` (saved with every checkpoint)."""

    width: int = 128
    heads: int = 4
    latents: int = 64
    depth: int = 4  # self-attention blocks on the latents
    decoder_layers: int = 2  # cross-attention blocks points <- latents
    cond_dim: int = 384
    n_freq: int = 6  # Fourier features of the coordinates
    coarse: bool = False  # upsampler: conditioned on a coarse cloud
    tokens: int = 0  # per-token conditioning: read this many text-encoder token states

    def to_dict(self) -> dict:
        return asdict(self)


class Attention(nn.Module):
    """Multi-head attention ``softmax(Q K^T / sqrt(d)) V``. With gradients it is written out
    (on this CPU the plain matmuls train faster than ``scaled_dot_product_attention``'s
    backward); without, the fused kernel runs."""

    def __init__(self, width: int, heads: int) -> None:
        super().__init__()
        self.heads = heads
        self.q = nn.Linear(width, width)
        self.kv = nn.Linear(width, 2 * width)
        self.out = nn.Linear(width, width)

    def forward(self, x: torch.Tensor, ctx: torch.Tensor,
                weight: torch.Tensor | None = None) -> torch.Tensor:
        """``weight`` (B, M) in [0, 1]: how much each context entry takes part (None: all
        fully); attention logits get ``log(weight + 1e-30)``, so 0 removes an entry (its share
        is below float32 resolution), a blend of two conditions blends smoothly, and the
        gradient w.r.t. a weight stays finite at 0 (``log(0)`` would give ``inf * 0``)."""
        b, n, w = x.shape
        m, h = ctx.shape[1], self.heads
        q = self.q(x).view(b, n, h, w // h).transpose(1, 2)
        k, v = self.kv(ctx).view(b, m, 2, h, w // h).permute(2, 0, 3, 1, 4)
        bias = None if weight is None else torch.log(weight.clamp(0.0, 1.0) + 1e-30)[:, None,
                                                                                    None, :]
        if torch.is_grad_enabled():
            att = (q @ k.transpose(-1, -2)) * (w // h) ** -0.5
            y = (att if bias is None else att + bias).softmax(-1) @ v
        else:
            y = F.scaled_dot_product_attention(
                q, k, v, attn_mask=None if bias is None else bias.to(q.dtype))
        return self.out(y.transpose(1, 2).reshape(b, n, w))


class Block(nn.Module):
    """Pre-norm attention (self when ``ctx is None``) and MLP with residuals."""

    def __init__(self, width: int, heads: int) -> None:
        super().__init__()
        self.ln_x, self.ln_c, self.ln_m = (nn.LayerNorm(width) for _ in range(3))
        self.attn = Attention(width, heads)
        self.mlp = nn.Sequential(nn.Linear(width, 4 * width), nn.GELU(),
                                 nn.Linear(4 * width, width))

    def forward(self, x: torch.Tensor, ctx: torch.Tensor | None = None,
                weight: torch.Tensor | None = None) -> torch.Tensor:
        hx = self.ln_x(x)
        x = x + self.attn(hx, hx if ctx is None else self.ln_c(ctx), weight)
        return x + self.mlp(self.ln_m(x))


def fourier(x: torch.Tensor, n_freq: int) -> torch.Tensor:
    """``[x, sin(2^k pi x), cos(2^k pi x)]`` for k < n_freq (per coordinate)."""
    freqs = (2.0 ** torch.arange(n_freq, dtype=x.dtype, device=x.device)) * math.pi
    ang = x[..., None] * freqs
    return torch.cat([x, ang.sin().flatten(-2), ang.cos().flatten(-2)], -1)


def timestep_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Sinusoidal embedding of the (integer) diffusion timestep, as in DDPM."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, dtype=torch.float32,
                                                        device=t.device) / half)
    ang = t.float()[:, None] * freqs[None] * (1000.0 / T_TRAIN)
    return torch.cat([ang.cos(), ang.sin()], -1)


class PointDiffusionTransformer(nn.Module):
    """``eps = model(x_t, t, cond[, coarse])`` for clouds ``(B, N, 3)`` in model space."""

    def __init__(self, config: ModelConfig | None = None) -> None:
        super().__init__()
        c = self.config = config or ModelConfig()
        w, feat = c.width, 3 + 6 * c.n_freq
        self.point_in = nn.Linear(feat, w)
        self.time_mlp = nn.Sequential(nn.Linear(w, w), nn.SiLU(), nn.Linear(w, w))
        self.cond_in = nn.Linear(c.cond_dim, w)
        if c.tokens:  # token states join the latents' context; a null token is always there
            self.token_in = nn.Sequential(nn.LayerNorm(c.cond_dim), nn.Linear(c.cond_dim, w))
            self.token_null = nn.Parameter(torch.randn(1, 1, w) * 0.02)
        self.latents = nn.Parameter(torch.randn(c.latents, w) * 0.02)
        self.encoder = Block(w, c.heads)
        self.blocks = nn.ModuleList(Block(w, c.heads) for _ in range(c.depth))
        self.decoder = nn.ModuleList(Block(w, c.heads) for _ in range(c.decoder_layers))
        self.coarse_in = nn.Linear(feat, w) if c.coarse else None
        self.ln_out = nn.LayerNorm(w)
        self.out = nn.Linear(w, 3)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, x: torch.Tensor, t: torch.Tensor, cond: torch.Tensor,
                coarse: torch.Tensor | None = None) -> torch.Tensor:
        b, n = x.shape[:2]
        step = max(1, INFER_TOKENS // n)
        if torch.is_grad_enabled() or b <= step:
            return self._forward(x, t, cond, coarse)
        return torch.cat([self._forward(x[i:i + step], t[i:i + step], cond[i:i + step],
                                        None if coarse is None else coarse[i:i + step])
                          for i in range(0, b, step)])

    def _forward(self, x: torch.Tensor, t: torch.Tensor, cond: torch.Tensor,
                 coarse: torch.Tensor | None) -> torch.Tensor:
        c = self.config
        b = x.shape[0]
        temb = self.time_mlp(timestep_embedding(t, c.width).to(x.dtype))
        vec = cond[:, :c.cond_dim] if c.tokens else cond
        cemb = self.cond_in(vec.to(x.dtype))
        glob = (temb + cemb)[:, None]  # (B, 1, W)
        h = self.point_in(fourier(x, c.n_freq)) + glob
        extra = [temb[:, None], cemb[:, None]]
        if self.coarse_in is not None:
            if coarse is None:
                raise ValueError("the upsampler needs the coarse cloud")
            extra.append(self.coarse_in(fourier(coarse, c.n_freq)) + glob)
        z = self.latents.expand(b, -1, -1)
        words, enc_weight, lat_weight = self._tokens(cond, b, h.shape[1] + len(extra)) \
            if c.tokens else ([], None, None)
        z = self.encoder(z, torch.cat([h, *extra, *words], 1), enc_weight)
        z = torch.cat([z, temb[:, None], cemb[:, None], *words], 1)
        for blk in self.blocks:
            z = blk(z, weight=lat_weight)
        z = z[:, :c.latents + 2]  # the decoder reads the latents (and time, condition)
        ctx = z if self.coarse_in is None else torch.cat([z, extra[2]], 1)
        for blk in self.decoder:
            h = blk(h, ctx)
        return self.out(self.ln_out(h))

    def _tokens(self, cond: torch.Tensor, b: int, n_before: int
                ) -> tuple[list[torch.Tensor], torch.Tensor, torch.Tensor]:
        """The token states of packed conditions (``text.encode_tokens``) as model tokens,
        with a null token in front, and the context weights of the encoder (``n_before``
        point and extra tokens first) and of the latent blocks."""
        from dbtool.prior.sampling.text import unpack_tokens

        c = self.config
        _, tok, weight = unpack_tokens(cond, c.tokens)
        words = torch.cat([self.token_null.expand(b, 1, -1).to(cond.dtype),
                           self.token_in(tok)], 1)
        ones = torch.ones(b, max(n_before, c.latents + 2) + 1, device=cond.device)
        weight = torch.cat([ones[:, :1], weight.float()], 1)
        return ([words], torch.cat([ones[:, :n_before], weight], 1),
                torch.cat([ones[:, :c.latents + 2], weight], 1))
