"""Training of the prior's two models on the procedural corpus, with checkpoints and resume.

The base model learns 1,024-point clouds conditioned on caption embeddings (cosine schedule,
condition dropped with p = 0.1); the upsampler learns the other 3,072 points of a 4,096-point
cloud given 1,024 of them (linear schedule, no text: the coarse cloud carries the shape). Each
step trains on a random subset of ``subset`` points per cloud: the model's cost is linear in the
points and a subset-trained model samples full clouds just as well
(measured on a prototype). Mixed precision uses bfloat16 autocast where the CPU has native
bfloat16 units (AMX, AVX512-BF16), float32 elsewhere (:mod:`dbtool.precision`).

A run directory holds ``config.json``, ``manifest.json``, ``metrics.jsonl`` (the loss log) and
``checkpoint.pt`` (model, EMA, optimiser, RNG states), written atomically every
``ckpt_every`` steps; ``resume=True`` continues from it after an interruption.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from dbtool.atomic import atomic_write, atomic_write_text
from dbtool.errors import InputError, MissingFileError, PathError
from dbtool.precision import use_bf16
from dbtool.prior.corpora.versions import CORPORA, corpus_digest, corpus_module
from dbtool.prior.sampling import text
from dbtool.prior.sampling.diffusion import P_UNCOND, SCALE, diffusion_loss
from dbtool.prior.sampling.model import ModelConfig, PointDiffusionTransformer
from dbtool.prior.sampling.schedulers import NoiseSchedule, schedule_for

COARSE = 1024
FINE = 4096


@dataclass
class TrainConfig:
    """Everything a training run depends on (written to ``config.json``)."""

    kind: str = "base"  # "base" or "upsampler"
    steps: int = 10000
    batch: int = 32
    subset: int = 256  # points per cloud per step (noised points for the upsampler)
    lr: float = 1e-3
    lr_min: float = 5e-5
    warmup: int = 200
    weight_decay: float = 0.01
    ema: float = 0.999
    token_drop: float = 0.2  # per-token models: share of steps conditioned on the sentence alone
    per_family: int = 300  # training shapes per family
    corpus: int = 1  # 1: corpora/shapes.py (version 1), 2: corpora/corpus.py, 3: corpora/corpus3.py
    corpus_digest: str = ""  # hash of the corpus the run started with (set by train)
    seed: int = 0
    threads: int = 1
    bf16: bool | None = None  # bfloat16 autocast; None: where the CPU has it natively
    compile: bool = False  # torch.compile the training forward (1.6x faster in float32 here)
    ckpt_every: int = 250
    log_every: int = 25
    model: ModelConfig = field(default_factory=ModelConfig)
    init: str = ""  # a checkpoint whose model and EMA weights start the run (a fine-tune)

    def __post_init__(self) -> None:
        if self.kind not in ("base", "upsampler"):
            raise InputError(f"unknown model kind {self.kind!r}: base or upsampler")
        if isinstance(self.model, dict):
            self.model = ModelConfig(**self.model)
        self.model.coarse = self.kind == "upsampler"
        if self.corpus not in CORPORA:
            raise InputError(f"unknown corpus version {self.corpus}: "
                             f"{' or '.join(map(str, CORPORA))}")


def preset(kind: str, **overrides) -> TrainConfig:
    """The configuration the shipped weights were trained with (``MODEL_CARD.md``): on the
    attribute corpus (``corpus=2``) the base model trains for 24,000 steps; on corpus 3 for
    30,000 steps with per-token conditioning (24 token states, chosen from the measurements of
    ``benchmarks/prior_scaling.py``, docs/prior.md)."""
    if kind == "base":
        corpus = overrides.get("corpus")
        steps = {2: 24000, 3: 30000}.get(corpus, 14000)
        cfg = TrainConfig(kind="base", steps=steps, batch=32, subset=256, ckpt_every=500,
                          model=ModelConfig(depth=6, tokens=24 if corpus == 3 else 0))
    elif kind == "upsampler":
        cfg = TrainConfig(kind="upsampler", steps=4000, batch=16, subset=256, ckpt_every=250)
    else:
        raise InputError(f"unknown model kind {kind!r}: base or upsampler")
    for key, value in overrides.items():
        if value is not None:
            setattr(cfg, key, value)
    return cfg


def finetune_config(init: Path, **overrides) -> TrainConfig:
    """A run that starts from the weights of the checkpoint ``init`` (its model, EMA and
    model configuration; a fresh optimiser and learning-rate schedule): by default 8,000 steps
    from ``lr = 3e-4``, on the checkpoint's corpus version as the code builds it now."""
    saved = checkpoint_config(Path(init))
    cfg = TrainConfig(**{**saved, "corpus_digest": "", "steps": 8000, "lr": 3e-4,
                         "warmup": 100, "init": str(init)})
    for key, value in overrides.items():
        if value is not None:
            setattr(cfg, key, value)
    return cfg


def checkpoint_config(ckpt_path: Path) -> dict:
    """The training configuration saved in the checkpoint ``ckpt_path``."""
    if not ckpt_path.is_file():
        raise MissingFileError(f"no training checkpoint at {ckpt_path}")
    try:
        return torch.load(ckpt_path, weights_only=True, map_location="cpu")["config"]
    except Exception as exc:  # noqa: BLE001 - any unreadable checkpoint gets one message
        raise InputError(f"not a readable training checkpoint: {ckpt_path}") from exc


def resumed_config(run_dir: Path, steps: int | None = None) -> TrainConfig:
    """The configuration saved in ``run_dir/checkpoint.pt`` (optionally with more steps)."""
    ckpt_path = Path(run_dir) / "checkpoint.pt"
    if not ckpt_path.is_file():
        raise MissingFileError(f"nothing to resume: {ckpt_path} does not exist")
    cfg = TrainConfig(**checkpoint_config(ckpt_path))
    if steps is not None:
        cfg.steps = steps
    return cfg


def atomic_save(obj, path: Path) -> None:
    atomic_write(path, lambda tmp: torch.save(obj, tmp))


def load_corpus(cfg: TrainConfig, cache_dir: Path, progress=None):
    """Training clouds (4,096 points, float16), family labels, caption table and, per shape,
    the indices of its captions. Cached as ``.npz`` keyed by seed and size."""
    mod = corpus_module(cfg.corpus)
    tag = "" if cfg.corpus == 1 else f"v{cfg.corpus}-{cfg.corpus_digest or corpus_digest(mod)}-"
    path = cache_dir / f"corpus-{tag}seed{cfg.seed}-{cfg.per_family}x{len(mod.FAMILIES)}.npz"
    if path.exists():
        d = np.load(path, allow_pickle=False)
        caps = [str(c) for c in d["captions"]]
        return d["clouds"], d["labels"], caps, list(d["cap_index"]), d["cap_count"]
    clouds, labels, caps = mod.make_corpus(cfg.per_family, "train", cfg.seed, FINE,
                                           progress=progress)
    table = sorted({c for cs in caps for c in cs})
    pos = {c: i for i, c in enumerate(table)}
    width = max(len(cs) for cs in caps)
    cap_index = np.full((len(caps), width), -1, np.int32)
    for i, cs in enumerate(caps):
        cap_index[i, : len(cs)] = [pos[c] for c in cs]
    cap_count = np.array([len(cs) for cs in caps], np.int32)
    atomic_write(path, lambda tmp: np.savez(
        tmp, clouds=clouds.astype(np.float16), labels=labels, captions=np.array(table),
        cap_index=cap_index, cap_count=cap_count))
    return clouds.astype(np.float16), labels, table, list(cap_index), cap_count


def caption_embeddings(cfg: TrainConfig, table: list[str], cache_dir: Path,
                       chunk: int = 4096) -> torch.Tensor:
    """The text embeddings of the corpus's caption table. Corpus 2 has tens of thousands of
    captions, so they are cached next to the corpus, chunk by chunk (an interrupted encoding
    resumes)."""
    tokens = cfg.model.tokens
    if cfg.corpus == 1 and not tokens:
        return text.encode(table)
    from tqdm import tqdm

    digest = hashlib.sha256("\n".join(table).encode()).hexdigest()[:10]
    base = cache_dir / (f"captions-v{cfg.corpus}-{digest}" + (f"-tok{tokens}" if tokens else ""))
    parts = []
    for k in tqdm(range(0, len(table), chunk), desc="caption embeddings", unit="chunk"):
        path = Path(f"{base}-{k // chunk:04d}.npy")
        if path.exists():
            parts.append(np.load(path))
            continue
        batch = table[k: k + chunk]
        vecs = (text.encode_tokens(batch, tokens).numpy().astype(np.float16) if tokens else
                text.encode(batch).numpy().astype(np.float32))
        atomic_write(path, lambda tmp, v=vecs: np.save(tmp, v))
        parts.append(vecs)
    return torch.from_numpy(np.concatenate(parts))  # float16 for packed token states


def lr_at(cfg: TrainConfig, step: int) -> float:
    """Linear warm-up, then cosine decay to ``lr_min``."""
    if step < cfg.warmup:
        return cfg.lr * (step + 1) / cfg.warmup
    u = (step - cfg.warmup) / max(1, cfg.steps - cfg.warmup)
    return cfg.lr_min + 0.5 * (cfg.lr - cfg.lr_min) * (1 + math.cos(math.pi * min(u, 1.0)))


def make_batch(cfg: TrainConfig, clouds, cap_index, cap_count, emb, rng: np.random.Generator):
    """(x0, cond, coarse) in model space for one step."""
    idx = rng.integers(0, len(clouds), cfg.batch)
    pts = clouds[idx].astype(np.float32)  # (B, 4096, 3)
    perm = np.argsort(rng.random((cfg.batch, FINE)), axis=1)
    if cfg.kind == "base":
        x0 = np.take_along_axis(pts, perm[:, : cfg.subset, None], 1)
        coarse = None
        which = (rng.random(cfg.batch) * cap_count[idx]).astype(int)
        cond = emb[np.array([cap_index[i][w] for i, w in zip(idx, which, strict=True)])].float()
        if cfg.model.tokens:  # some steps see the sentence alone (co-design's free embedding)
            cond[rng.random(cfg.batch) < cfg.token_drop, text.DIM:] = 0.0
    else:
        coarse = torch.from_numpy(np.take_along_axis(pts, perm[:, :COARSE, None], 1) * SCALE)
        x0 = np.take_along_axis(pts, perm[:, COARSE: COARSE + cfg.subset, None], 1)
        cond = torch.zeros(cfg.batch, cfg.model.cond_dim)
    return torch.from_numpy(x0 * SCALE), cond, coarse


class RunExistsError(PathError, FileExistsError):
    """A training run would overwrite another run's checkpoint."""


@dataclass
class TrainState:
    """What a training run carries from step to step (and saves in ``checkpoint.pt``)."""

    model: PointDiffusionTransformer
    ema: PointDiffusionTransformer
    opt: torch.optim.Optimizer
    rng: np.random.Generator
    gen: torch.Generator
    start: int = 0
    elapsed: float = 0.0


def check_corpus(cfg: TrainConfig, run_dir: Path) -> None:
    """Record the corpus's hash in ``cfg``; refuse to resume a run on a changed corpus."""
    digest = corpus_digest(corpus_module(cfg.corpus))
    if cfg.corpus_digest and cfg.corpus_digest != digest:
        raise InputError(f"the corpus changed since {run_dir} started (corpus "
                         f"{cfg.corpus_digest}, now {digest}); a resumed run would train on "
                         "other shapes: start a new run")
    cfg.corpus_digest = digest  # kept in the checkpoint's config


def initial_state(cfg: TrainConfig, ckpt_path: Path, run_dir: Path) -> TrainState:
    """A fresh model, EMA copy, optimiser and RNGs (seeded), or those of ``ckpt_path``."""
    torch.manual_seed(cfg.seed)
    model = PointDiffusionTransformer(cfg.model)
    ema = copy.deepcopy(model).requires_grad_(False)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    state = TrainState(model, ema, opt, np.random.default_rng(cfg.seed),
                       torch.Generator().manual_seed(cfg.seed))
    if ckpt_path.exists():
        ck = torch.load(ckpt_path, weights_only=True)
        model.load_state_dict(ck["model"])
        ema.load_state_dict(ck["ema"])
        opt.load_state_dict(ck["opt"])
        state.rng.bit_generator.state = ck["rng"]
        state.gen.set_state(ck["gen"])
        state.start, state.elapsed = ck["step"], ck["elapsed"]
        if cfg.steps < state.start:
            raise InputError(f"{run_dir} is already at step {state.start}; --train-steps "
                             f"{cfg.steps} would go back")
    elif cfg.init:
        if not Path(cfg.init).is_file():
            raise MissingFileError(f"the checkpoint to start from does not exist: {cfg.init}")
        ck = torch.load(cfg.init, weights_only=True, map_location="cpu")
        model.load_state_dict(ck["model"])
        ema.load_state_dict(ck["ema"])
    return state


def save_state(state: TrainState, cfg: TrainConfig, step: int, ckpt_path: Path) -> None:
    atomic_save({"model": state.model.state_dict(), "ema": state.ema.state_dict(),
                 "opt": state.opt.state_dict(), "rng": state.rng.bit_generator.state,
                 "gen": state.gen.get_state(), "step": step, "elapsed": state.elapsed,
                 "config": asdict(cfg)}, ckpt_path)


def train_step(cfg: TrainConfig, state: TrainState, fwd, schedule: NoiseSchedule, step: int,
               data: tuple) -> float:
    """One optimiser step (learning rate, batch, loss, clipped update, EMA); the loss."""
    model, opt = state.model, state.opt
    for g in opt.param_groups:
        g["lr"] = lr_at(cfg, step)
    x0, cond, coarse = make_batch(cfg, *data, state.rng)

    def net(x, t, c, coarse=coarse):
        return fwd(x, t, c, coarse)

    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=use_bf16("cpu", cfg.bf16)):
        loss = diffusion_loss(schedule, net, x0, cond, state.gen,
                              p_uncond=P_UNCOND if cfg.kind == "base" else 0.0)
    opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
    opt.step()
    decay = min(cfg.ema, (1 + step) / (10 + step))
    with torch.no_grad():
        for pe, pm in zip(state.ema.parameters(), model.parameters(), strict=True):
            pe.lerp_(pm, 1 - decay)
    return loss.item()


def train(cfg: TrainConfig, run_dir: Path, resume: bool = False, cache_dir: Path | None = None,
          show_progress: bool = True) -> dict:
    """Train (or resume) one model; returns the final metrics. ``show_progress``: a tqdm bar.
    Records the corpus's hash in ``cfg`` and refuses to resume on a changed corpus."""
    from dbtool.runs import RunDir, write_json

    torch.set_num_threads(max(1, cfg.threads))
    ckpt_path = Path(run_dir) / "checkpoint.pt"
    if ckpt_path.exists() and not resume:
        raise RunExistsError(f"{ckpt_path} exists: pass --resume or choose another --out")
    check_corpus(cfg, run_dir)
    run = RunDir(run_dir, asdict(cfg), cfg.seed, "cpu", kind="prior-train", keep_metrics=True)
    clouds, _labels, table, cap_index, cap_count = load_corpus(
        cfg, cache_dir or run.path.parent / "corpus")
    emb = caption_embeddings(cfg, table, cache_dir or run.path.parent / "corpus") \
        if cfg.kind == "base" else None
    state = initial_state(cfg, ckpt_path, run_dir)
    start = state.start
    # compiled: fused kernels for the forward and backward (the weights stay ``model``'s)
    fwd = torch.compile(state.model) if cfg.compile else state.model
    # the loss log holds exactly the steps the checkpoint has seen (a crash after the last
    # checkpoint leaves rows that the resumed run will write again)
    kept = [r for r in read_log(run.path) if r.get("step", 0) <= start]
    atomic_write_text(run.path / "metrics.jsonl", "".join(json.dumps(r) + "\n" for r in kept))
    schedule = schedule_for(cfg.kind)

    bar = None
    if show_progress:
        from tqdm import tqdm

        bar = tqdm(total=cfg.steps, initial=start, desc=f"train {cfg.kind}", unit="step")
    window: list[float] = []
    t0 = time.perf_counter()
    step = start
    for step in range(start, cfg.steps):
        window.append(train_step(cfg, state, fwd, schedule, step,
                                 (clouds, cap_index, cap_count, emb)))
        if bar is not None:
            bar.update(1)
            bar.set_postfix(loss=f"{np.mean(window[-50:]):.4f}")
        if (step + 1) % cfg.log_every == 0:
            now = time.perf_counter()
            state.elapsed += now - t0
            t0 = now
            run.log(step=step + 1, loss=float(np.mean(window)), lr=lr_at(cfg, step),
                    elapsed_s=round(state.elapsed, 1))
            window = []
        if (step + 1) % cfg.ckpt_every == 0:
            save_state(state, cfg, step + 1, ckpt_path)
    state.elapsed += time.perf_counter() - t0
    save_state(state, cfg, cfg.steps, ckpt_path)
    if bar is not None:
        bar.close()
    result = {"steps": cfg.steps, "elapsed_s": state.elapsed}
    write_json(run.path / "metrics.json", result)
    run.close()
    return result


def export_weights(checkpoint: Path, out: Path) -> Path:
    """Write the EMA weights and the model config of a checkpoint as a shippable file."""
    if not Path(checkpoint).is_file():
        raise MissingFileError(f"checkpoint not found: {checkpoint}")
    try:
        ck = torch.load(checkpoint, weights_only=True, map_location="cpu")
        cfg = ck["config"]
        ck["ema"], ck["step"], ck["elapsed"]  # noqa: B018 - the fields a weights file needs
    except Exception as exc:  # noqa: BLE001 - any unreadable checkpoint gets one message
        raise InputError(f"not a dbtool training checkpoint: {checkpoint}") from exc
    state = {k: v.to(torch.float32) for k, v in ck["ema"].items()}
    log = read_log(checkpoint.parent)
    tail = [r["loss"] for r in log[-20:]]  # the last 20 logged windows (500 steps by default)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_save({"kind": cfg["kind"], "model": cfg["model"], "state": state,
                 "steps": ck["step"], "train_seconds": ck["elapsed"],
                 "final_loss": float(np.mean(tail)) if tail else None,
                 "train_config": cfg, "schedule": schedule_for(cfg["kind"]).config()}, out)
    return out


def read_log(run_dir: Path) -> list[dict]:
    path = Path(run_dir) / "metrics.jsonl"
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
