"""The prior as one object: shipped weights, prompts -> point clouds, intermediate x_t.

:class:`Prior` keeps the model, its schedulers (:mod:`dbtool.prior.sampling.schedulers`) and the
text encoder apart (diffusers-style) and is the only thing the co-design code talks to. Any
backbone with the call signature ``eps = backbone(x_t, t, cond)`` (clouds ``(B, N, 3)`` in
model space, integer timesteps, ``(B, 384)`` conditions) can replace the shipped transformer,
e.g. a GPU-trained model or real Point-E weights behind an adapter: pass it as
``Prior(base=...)``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from dbtool.choices import PRIOR_VERSION
from dbtool.errors import InputError
from dbtool.precision import use_bf16
from dbtool.prior.sampling import text
from dbtool.prior.sampling.diffusion import SCALE, EpsModel, Step, denoise
from dbtool.prior.sampling.model import ModelConfig, PointDiffusionTransformer
from dbtool.prior.sampling.schedulers import (
    DDIMScheduler,
    DDPMScheduler,
    NoiseSchedule,
    Scheduler,
    schedule_for,
)

WEIGHTS_ROOT = Path(__file__).parents[1] / "weights"  # dbtool/prior/weights
DEFAULT_VERSION = PRIOR_VERSION  # the shipped prior; every version keeps its folder weights/vN


CONFIG = "config.json"  # in a weights folder: the noise schedules its models were trained with


def weights_dir(version: int = DEFAULT_VERSION) -> Path:
    """The folder of the shipped weights of prior ``version`` (base.pt, upsampler.pt,
    config.json, eval.json)."""
    path = WEIGHTS_ROOT / f"v{version}"
    if not path.is_dir():
        known = sorted(p.name for p in WEIGHTS_ROOT.glob("v*") if p.is_dir())
        raise CheckpointError(f"no shipped prior version {version}; shipped: "
                              f"{', '.join(known) or 'none'}")
    return path


WEIGHTS = WEIGHTS_ROOT / f"v{DEFAULT_VERSION}"
BASE_WEIGHTS = WEIGHTS / "base.pt"
UPSAMPLER_WEIGHTS = WEIGHTS / "upsampler.pt"
COARSE_POINTS = 1024
FINE_POINTS = 4096
MAX_GUIDANCE = 50.0


class CheckpointError(InputError):
    """A weights file is missing or is not a dbtool prior checkpoint."""


def weights_config(folder: Path) -> dict:
    """A weights folder's ``config.json`` (``{"schedules": {kind: NoiseSchedule.config()}}``,
    ``"upsampler_from": N`` where the version uses version N's upsampler and
    ``"guidance_interval": [LO, HI]`` where its guidance is limited to those steps), ``{}`` where
    the folder has none."""
    path = Path(folder) / CONFIG
    if not path.is_file():
        return {}
    try:
        config = json.loads(path.read_text())
    except ValueError as exc:
        raise CheckpointError(f"not a readable weights configuration: {path}") from exc
    if not isinstance(config, dict):
        raise CheckpointError(f"not a weights configuration: {path}")
    return config


def model_schedule(kind: str, meta: dict, config: dict) -> NoiseSchedule:
    """The noise schedule the ``kind`` model was trained with: the one its weights file
    records (``meta["schedule"]``, :func:`~dbtool.prior.training.train.export_weights`), else
    the one its weights folder's ``config`` gives, else the one ``kind`` trains with."""
    saved = meta.get("schedule") or config.get("schedules", {}).get(kind)
    return NoiseSchedule.from_config(saved) if saved else schedule_for(kind)


def load_model(path: str | Path, kind: str | None = None) -> tuple[PointDiffusionTransformer,
                                                                    dict]:
    """A model and its metadata from a file written by
    :func:`~dbtool.prior.training.train.export_weights` (or a training ``checkpoint.pt``, whose
    EMA weights are used). ``kind`` (``"base"`` or
    ``"upsampler"``), when given, must match the file's. Files are read with
    ``weights_only=True``: a checkpoint cannot run code."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint not found: {path}")
    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unreadable file gets the same one-line error
        raise CheckpointError(f"not a readable checkpoint: {path} ({exc.__class__.__name__})"
                              ) from exc
    if not isinstance(ck, dict) or not ({"state", "model"} <= ck.keys()
                                        or {"ema", "config"} <= ck.keys()):
        raise CheckpointError(f"not a dbtool prior checkpoint: {path}")
    if "ema" in ck:  # training checkpoint
        config = ck["config"]
        if not isinstance(config, dict):
            raise CheckpointError(f"{path}: the training checkpoint's config is not a "
                                  "dictionary")
        meta = {"kind": config.get("kind"), "model": config.get("model"),
                "steps": ck.get("step"), "train_seconds": ck.get("elapsed"),
                "train_config": config}
        state = ck["ema"]
    else:
        meta, state = {k: v for k, v in ck.items() if k != "state"}, ck["state"]
    if meta.get("kind") not in ("base", "upsampler"):
        raise CheckpointError(f"{path} does not say which model it holds (its kind must be "
                              f"base or upsampler, not {meta.get('kind')!r})")
    if kind is not None and meta.get("kind") != kind:
        raise CheckpointError(f"{path} holds the {meta.get('kind')} model, not the {kind} model")
    check_meta(path, meta)
    cfg = model_config(path, meta["model"])
    check_state(path, cfg, state)
    try:
        model = PointDiffusionTransformer(cfg)
        model.load_state_dict(state)
    except (TypeError, RuntimeError, ValueError) as exc:
        raise CheckpointError(f"{path}: weights do not match the model they describe") from exc
    model.eval().requires_grad_(False)
    return model, meta


MAX_SIZE = 1 << 16  # any size of a model config (the shipped models: width 128, 6 blocks)


def model_config(path: Path, model: object) -> ModelConfig:
    """The ``model`` entry of a weights file as a :class:`ModelConfig`: a dictionary of its
    fields, each an integer in ``0 .. 65536`` (``coarse``: true or false)."""
    from dataclasses import fields

    if not isinstance(model, dict):
        raise CheckpointError(f"{path}: the model description is not a dictionary")
    known = {f.name: f for f in fields(ModelConfig)}
    unknown = sorted(set(model) - set(known))
    if unknown:
        raise CheckpointError(f"{path}: unknown model setting(s) {', '.join(map(str, unknown))}")
    for name, value in model.items():
        if name == "coarse":
            if not isinstance(value, bool):
                raise CheckpointError(f"{path}: model setting coarse must be true or false, "
                                      f"not {value!r}")
        elif isinstance(value, bool) or not isinstance(value, int) or \
                not 0 <= value <= MAX_SIZE:
            raise CheckpointError(f"{path}: model setting {name} must be an integer from 0 to "
                                  f"{MAX_SIZE}, not {value!r}")
    return ModelConfig(**model)


def check_state(path: Path, cfg: ModelConfig, state: object) -> None:
    """``state`` holds a finite tensor of the right shape for every parameter of the model
    ``cfg`` describes, and nothing else. The model is laid out on PyTorch's ``meta`` device
    first, so a file that describes a huge model costs no memory."""
    if not isinstance(state, dict) or not all(
            isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in state.items()):
        raise CheckpointError(f"{path}: the weights are not a dictionary of tensors")
    try:
        with torch.device("meta"):
            shapes = {k: tuple(v.shape)
                      for k, v in PointDiffusionTransformer(cfg).state_dict().items()}
    except (TypeError, RuntimeError, ValueError, ZeroDivisionError) as exc:
        raise CheckpointError(f"{path}: its model description {cfg} is not a model "
                              f"({exc.__class__.__name__})") from exc
    got = {k: tuple(v.shape) for k, v in state.items()}
    if got != shapes:
        raise CheckpointError(f"{path}: weights do not match the model they describe")
    for k, v in state.items():
        if v.is_floating_point() and not bool(torch.isfinite(v).all()):
            raise CheckpointError(f"{path}: the weights hold NaN or infinite values ({k})")


def check_meta(path: Path, meta: dict) -> None:
    """The entries of a weights file read besides the weights: ``schedule`` (a noise schedule
    as :meth:`NoiseSchedule.config` writes it) and ``train_config`` (a dictionary whose
    ``corpus`` is an integer >= 1)."""
    saved = meta.get("schedule")
    if saved is not None:
        if not isinstance(saved, dict) or not isinstance(saved.get("T", 1024), int) or \
                isinstance(saved.get("T"), bool) or not 1 <= saved.get("T", 1024) <= MAX_SIZE:
            raise CheckpointError(f"{path}: not a noise schedule: {saved!r}"[:200])
        try:
            schedule = NoiseSchedule.from_config(saved)
            ok = bool(torch.isfinite(schedule.abar).all() and (schedule.abar > 0).all())
        except (InputError, TypeError, ValueError, RuntimeError) as exc:
            raise CheckpointError(f"{path}: not a noise schedule: {saved!r}"[:200]) from exc
        if not ok:
            raise CheckpointError(f"{path}: not a usable noise schedule: {saved!r}"[:200])
    train = meta.get("train_config", meta)
    if not isinstance(train, dict):
        raise CheckpointError(f"{path}: train_config is not a dictionary")
    corpus = train.get("corpus", 1)
    if isinstance(corpus, bool) or not isinstance(corpus, int) or corpus < 1:
        raise CheckpointError(f"{path}: the corpus version must be an integer >= 1, not "
                              f"{corpus!r}")


@dataclass
class Samples:
    """Generated clouds in ``[-0.5, 0.5]^3`` (y up) and, on request, x_t at chosen t."""

    clouds: np.ndarray  # (n, points, 3)
    intermediates: dict[int, np.ndarray] = field(default_factory=dict)  # t -> (n, points, 3)
    fine: np.ndarray | None = None  # upsampled (n, 4096, 3)


class Prior:
    """Text/embedding-conditioned point-cloud diffusion with an optional upsampler.

    ``scheduler`` samples the base model (default: strided DDPM on the cosine schedule it was
    trained with), ``up_scheduler`` the upsampler (default: DDIM on the linear schedule); a
    scheduler on another schedule than the model's training schedule gives wrong samples.
    :meth:`load` builds both on the schedules stored with the weights."""

    def __init__(self, base: EpsModel, upsampler: PointDiffusionTransformer | None = None,
                 bf16: bool | None = None, scheduler: Scheduler | None = None,
                 up_scheduler: Scheduler | None = None) -> None:
        self.base, self.upsampler, self.bf16 = base, upsampler, bf16
        self.corpus = 1  # the corpus version the base model was trained on (set by load)
        # (t_lo, t_hi): guidance only at these steps (a weights folder's config sets it)
        self.guidance_interval: tuple[int, int] | None = None
        self.scheduler = scheduler or DDPMScheduler(schedule_for("base"))
        self.up_scheduler = up_scheduler or DDIMScheduler(schedule_for("upsampler"))

    @classmethod
    def load(cls, base: str | Path | None = None, upsampler: str | Path | None = None,
             with_upsampler: bool = True, version: int | None = None,
             **schedulers: Scheduler) -> Prior:
        """The shipped weights of ``version`` (default: ``DEFAULT_VERSION``) or the given
        files; the upsampler is loaded when ``with_upsampler`` or a path is given.
        ``schedulers``: ``scheduler`` and/or ``up_scheduler`` (see :class:`Prior`); by default
        DDPM and DDIM on the noise schedules stored with the weights (:func:`model_schedule`)."""
        folder = weights_dir(version) if version is not None else WEIGHTS
        config = weights_config(folder)
        model, meta = load_model(base or folder / "base.pt", "base")
        if not schedulers.get("scheduler"):
            schedulers["scheduler"] = DDPMScheduler(
                model_schedule("base", meta, config if base is None else {}))
        up = None
        if with_upsampler or upsampler is not None:
            # a version may ship the upsampler of an earlier one (it reads no text)
            up_file = (weights_dir(int(config["upsampler_from"])) if "upsampler_from" in config
                       else folder) / "upsampler.pt"
            if upsampler is None and not up_file.is_file():
                raise CheckpointError(f"the shipped prior {folder.name} has no upsampler; load "
                                      "it with with_upsampler=False or give an upsampler file")
            up, up_meta = load_model(upsampler or up_file, "upsampler")
            if not schedulers.get("up_scheduler"):
                schedulers["up_scheduler"] = DDIMScheduler(model_schedule(
                    "upsampler", up_meta, config if upsampler is None else {}))
        prior = cls(model, up, **schedulers)
        prior.corpus = int(meta.get("train_config", meta).get("corpus", 1))
        if base is None and config.get("guidance_interval"):
            lo, hi = config["guidance_interval"]
            prior.guidance_interval = (int(lo), int(hi))
        return prior

    # ------------------------------------------------------------------ conditions
    @property
    def tokens(self) -> int:
        """How many text-encoder token states the base model reads (0: the sentence
        embedding alone)."""
        return int(getattr(getattr(self.base, "config", None), "tokens", 0))

    @property
    def cond_dim(self) -> int:
        """Width of the base model's condition vectors (:func:`text.cond_dim`)."""
        return text.cond_dim(self.tokens)

    def null(self) -> torch.Tensor:
        """The unconditional condition, ``(1, cond_dim)`` zeros (the condition dropped in
        training, docs/method.md §1)."""
        return torch.zeros(1, self.cond_dim)

    def embed(self, prompts: Sequence[str] | str) -> torch.Tensor:
        """Prompt conditions, shape ``(len, cond_dim)``: the sentence embeddings (384), with
        the packed token states for a model that reads them (:func:`text.encode_tokens`)."""
        plist = list(prompts) if not isinstance(prompts, str) else [prompts]
        return text.encode_tokens(plist, self.tokens) if self.tokens else text.encode(plist)

    def eps(self, x: torch.Tensor, t: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """The base model's epsilon (bfloat16 autocast on ``x``'s device when ``bf16``, by
        default where it is native: :mod:`dbtool.precision`)."""
        with torch.autocast(x.device.type, dtype=torch.bfloat16,
                            enabled=use_bf16(x.device.type, self.bf16)):
            return self.base(x, t, cond).float()

    # ------------------------------------------------------------------ sampling
    def denoising_loop(self, conds: Sequence[tuple[torch.Tensor, float]], n: int, steps: int = 64,
                seed: int = 0, points: int = COARSE_POINTS, include: Sequence[int] = (),
                t_start: int | None = None, x_T: torch.Tensor | None = None,
                scheduler: Scheduler | None = None, generator: torch.Generator | None = None,
                start: int = 0) -> Iterator[Step]:
        """The base model's denoising loop (steps by ``scheduler``, default :attr:`scheduler`)
        as a generator of :class:`Step` (model space, see
        :func:`~dbtool.prior.sampling.diffusion.denoise`); the caller may replace ``step.x``
        between updates. ``generator`` (default: seeded by ``seed``) draws x_T and the
        updates' noise; with ``start`` and ``x_T`` the loop resumes at that step."""
        for c, s, *_ in conds:
            if not np.isfinite(s) or abs(s) > MAX_GUIDANCE:
                raise InputError(f"guidance scale {s} is outside [-{MAX_GUIDANCE}, "
                                 f"{MAX_GUIDANCE}]")
            if c.dim() != 2 or c.shape[-1] != self.cond_dim:
                raise ValueError(f"a condition must have shape (1 or n, {self.cond_dim})")
        gen = torch.Generator().manual_seed(seed) if generator is None else generator
        if x_T is None:
            x_T = torch.randn((n, points, 3), generator=gen)
        return denoise(scheduler or self.scheduler, self.eps, x_T, conds, steps, t_start,
                       include, gen, self.guidance_interval, start)

    def sample(self, prompts: Sequence[str] | str | None = None, n: int = 1,
               guidance: float = 3.0, steps: int = 64, seed: int = 0,
               embedding: torch.Tensor | None = None, extra: Sequence[tuple[str | torch.Tensor,
               float]] = (), return_at: Sequence[int] = (), upsample: bool = False,
               points: int = COARSE_POINTS, scheduler: Scheduler | None = None) -> Samples:
        """``n`` clouds per prompt (or for ``embedding``: one, or one per sample),
        classifier-free guided.

        ``scheduler`` overrides :attr:`scheduler` (strided DDPM; DDPM gave sharper samples
        than DDIM, ``MODEL_CARD.md``). ``extra`` adds composed guidance terms
        ``(prompt or embedding, scale)`` (docs/method.md §6);
        ``return_at`` lists timesteps whose x_t is returned. They join the scheduler's strided
        grid, so a seed gives a slightly different x_0 with and without them (the same one
        for the same ``return_at``)."""
        conds: list[tuple[torch.Tensor, float]] = []
        if embedding is not None:
            emb = embedding.float()
            emb = emb.reshape(1, -1) if emb.dim() == 1 or emb.shape[0] == 1 else emb
            if emb.shape[0] not in (1, n):
                raise ValueError(f"{emb.shape[0]} embeddings for {n} samples; give 1 or n")
            conds.append((emb, guidance))
        elif prompts is not None:
            plist = [prompts] if isinstance(prompts, str) else list(prompts)
            emb = self.embed(plist).repeat_interleave(n, 0)
            conds.append((emb, guidance))
            n = n * len(plist)
        else:
            raise ValueError("give a prompt or an embedding")
        for c, s in extra:
            conds.append((self.embed(c) if isinstance(c, str) else c.reshape(1, -1), s))
        inter: dict[int, np.ndarray] = {}
        wanted = {int(t) for t in return_at}
        last = None
        for step in self.denoising_loop(conds, n, steps, seed, points, include=sorted(wanted),
                                 scheduler=scheduler):
            if step.t in wanted:
                inter[step.t] = step.x.numpy() / SCALE
            last = step
        clouds = last.x.numpy() / SCALE
        if 0 in wanted:
            inter[0] = clouds
        out = Samples(clouds, inter)
        if upsample:
            out.fine = self.upsample(clouds, seed=seed)
        return out

    def upsample(self, coarse: np.ndarray, steps: int = 32, seed: int = 0) -> np.ndarray:
        """Densify ``(n, 1024, 3)`` clouds to ``(n, 4096, 3)``: the coarse points plus 3,072
        new ones sampled from the upsampler."""
        if self.upsampler is None:
            raise RuntimeError("no upsampler weights loaded")
        c = torch.as_tensor(np.asarray(coarse, np.float32)) * SCALE
        n = c.shape[0]
        gen = torch.Generator().manual_seed(seed + 1)
        x_T = torch.randn((n, FINE_POINTS - c.shape[1], 3), generator=gen)
        null = text.null()

        def eps(x, t, cond):
            reps = x.shape[0] // n
            with torch.autocast(x.device.type, dtype=torch.bfloat16,
                                enabled=use_bf16(x.device.type, self.bf16)):
                return self.upsampler(x, t, cond, c.repeat(reps, 1, 1)).float()

        *_, last = denoise(self.up_scheduler, eps, x_T, [(null, 1.0)], steps, generator=gen)
        return np.concatenate([coarse, last.x.numpy() / SCALE], 1)
