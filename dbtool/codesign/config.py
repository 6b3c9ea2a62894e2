"""Settings of the method: the paper's Tables 4 and 5 per task, and the presets.

``paper`` holds the published values. ``quick`` runs the same algorithm with fewer samples,
epochs and co-design stops so a design finishes in minutes on a laptop CPU. Values that the
paper's tables do not give (epochs, embedding learning rate, denoising steps, guidance) are
dbtool's choices and say so.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from dbtool.errors import InputError
from dbtool.sim.task_names import N_STEPS
from dbtool.sim.task_names import NAMES as TASKS

# the string settings and the values each takes (a typo is an error, not another branch)
SPACES = ("mixture", "captions", "free")
TARGETS = ("x0", "xt")
GRADIENTS = ("scored", "straight")
HANDOVERS = ("best", "final")


def _choice(name: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise InputError(f"{name} must be one of {', '.join(allowed)}; got {value!r}")


# Text feedback (docs/method.md §6) guides the denoising loop only at t >= PROMPT_T_MIN: the prompt
# shapes the coarse body and the optimised embedding (with the physics term) finishes it, so the
# feedback adds the trait without overwriting the functional body (measured in
# docs/codesign-diffusion.md).
PROMPT_T_MIN = 350

@dataclass(frozen=True)
class EmbeddingConfig:
    """Algorithm 1 / Table 4 (the first six fields), then dbtool's own settings."""

    buffer_size: int
    min_buffer: int = 60
    samples_per_epoch: int = 60
    train_iters: int = 1
    top_k: int = 6
    batch_size: int = 6
    epochs: int = 20  # not in Table 4
    lr: float = 1.0  # Adam on the embedding's parameters (simplex logits); not in Table 4
    guidance: float = 3.0  # classifier-free guidance while sampling designs (Point-E's 3)
    sample_steps: int = 64  # strided denoising steps per design
    loss_guidance: float = 1.0  # guidance of the predictor trained (1: conditional, as paper)
    space: str = "mixture"  # where c lives: mixture of atoms | captions (convex hull) | free
    free_lr: float = 2e-3  # Adam on the raw 384-d c (space "free"; unit-norm captions)
    baseline: bool = False  # subtract the loss on the newest unfiltered samples
    elite: bool = False  # train on the top-k of the FIFO and of the best designs ever
    # no signal, no step: an epoch trains only when the buffer's scores spread by more than
    # this (task units; 0: always, as the paper). Where no design touches the task's object
    # the top-k are a random pick, and training on them steers c away from the prior
    signal: float = 0.0
    # share of each epoch's draws from the start mixture instead of the trained one (space
    # "mixture"; 0: none, as the paper)
    explore: float = 0.0

    def __post_init__(self) -> None:
        _choice("space", self.space, SPACES)
        if not 0.0 <= self.explore <= 1.0:
            raise InputError(f"explore must be between 0 and 1; got {self.explore}")


@dataclass(frozen=True)
class CodesignConfig:
    """Equations 6-7 / Table 5: Langevin stops at t_max, t_max - dt, ..., t_min, K steps each,
    noise sigma = sigma_beta * beta_t, physics weight kappa, controller step gamma, renorm."""

    t_max: int = 400
    t_min: int = 0
    dt: int = 50
    K: int = 5
    sigma_beta: float = 1e-4
    kappa: float = 1e4
    gamma: float = 0.001
    renorm: float = 10.0
    samples: int = 4  # co-designed samples; the best becomes the design (not in Table 5)
    step_scale: float = 1.0  # eta_t = min(step_scale * beta_t, 1 - abar_t); not in Table 5
    target: str = "x0"  # R evaluated on the denoiser's x0-estimate ("x0") or on x_t ("xt")
    min_move: float = 0.0  # floor of the physics displacement per stop (model-space RMS)
    smooth: bool = False  # physics gradient of the robot with smooth presence (no threshold)
    # dbtool's own (docs/method.md §5): the gradient of the scored robot (active sites only;
    # "straight": the straight-through gradient of the band too), the physics step's length
    # chosen by the simulator among these RMS displacements of the design (prior frame; empty:
    # the renorm-capped step), and the design handed over: the best one the chain evaluated
    # ("best") or its final sample ("final")
    gradient: str = "scored"
    search: tuple[float, ...] = (0.02, 0.04, 0.08)
    handover: str = "best"
    # co-design from the elite (dbtool/codesign/refine.py): after the ``samples`` fresh ones,
    # the best design so far is refined by ``refine`` steps at t = 0, the controller by
    # ``refine_gamma`` per step
    refine: int = 0
    refine_gamma: float = 0.0

    def __post_init__(self) -> None:
        _choice("target", self.target, TARGETS)
        _choice("gradient", self.gradient, GRADIENTS)
        _choice("handover", self.handover, HANDOVERS)

    @property
    def searching(self) -> bool:
        """Whether the physics step is chosen by the line search (else the fixed step)."""
        return self.kappa > 0 and bool(self.search) and self.target == "x0"


TABLE4 = {
    "balancing": EmbeddingConfig(buffer_size=600, top_k=12),
    "landing": EmbeddingConfig(buffer_size=600, top_k=12),
    "crawling": EmbeddingConfig(buffer_size=60),
    "hurdling": EmbeddingConfig(buffer_size=600),
    "gripping": EmbeddingConfig(buffer_size=60),
    "box": EmbeddingConfig(buffer_size=60),
}

TABLE5 = {
    "balancing": CodesignConfig(K=3, gamma=0.0),
    "landing": CodesignConfig(t_max=150, dt=25, K=3, gamma=0.0),
    "crawling": CodesignConfig(gamma=0.01),
    "hurdling": CodesignConfig(),
    "gripping": CodesignConfig(),
    "box": CodesignConfig(),
}

PRESETS = ("paper", "quick")
SIGNAL = 1e-6  # the quick preset's least score spread to train on: 1 um of task distance


def preset(name: str, task: str) -> tuple[EmbeddingConfig, CodesignConfig]:
    """The two configs of ``task`` under preset ``name``."""
    if task not in TABLE4:
        raise InputError(f"unknown task {task!r}; choose one of {', '.join(TASKS)}")
    if name not in PRESETS:
        raise InputError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    emb, cod = TABLE4[task], TABLE5[task]
    if name == "quick":
        ratio = emb.buffer_size // emb.samples_per_epoch  # epochs the buffer remembers
        emb = replace(emb, samples_per_epoch=12, min_buffer=12, buffer_size=12 * ratio,
                      top_k=3, batch_size=4, train_iters=4, epochs=4, sample_steps=32,
                      signal=SIGNAL)
        # fresh samples (on request) take five stops; co-design from the elite takes ten
        # refinement steps, the units of the two fresh samples the preset took before
        # (docs/method.md §5); both rescale the paper's drift budget
        paper = TABLE5[task]
        cod = replace(cod, dt=100, K=1, samples=0, refine=10)
        cod = replace(cod, step_scale=drift_budget(paper) / drift_budget(cod),
                      gamma=paper.gamma * n_steps(paper) / n_steps(cod),
                      refine_gamma=paper.gamma * n_steps(paper) / cod.refine)
    return emb, cod


def step_units(cfg: CodesignConfig, grad_cost: float) -> float:
    """Simulator units of one Langevin step: a gradient episode (``grad_cost`` forward
    episodes) plus one forward episode per line-search step length."""
    return grad_cost + (len(cfg.search) if cfg.searching else 0)


def n_steps(cfg: CodesignConfig) -> int:
    """Langevin steps per sample: K at each stop."""
    return cfg.K * len(range(cfg.t_max, cfg.t_min - 1, -cfg.dt))


def drift_budget(cfg: CodesignConfig) -> float:
    """``sum over stops of K * beta_t``: how far the Langevin steps of ``cfg`` can move x_t
    in all (per unit drift). ``quick`` takes fewer, longer steps with the same budget as the
    paper's schedule, via ``step_scale``."""
    from dbtool.prior.sampling.schedulers import schedule_for

    betas = schedule_for("base").betas
    return cfg.K * float(sum(betas[t] for t in range(cfg.t_max, cfg.t_min - 1, -cfg.dt)))


@dataclass
class Settings:
    """What the user asked for (``dbtool design`` options)."""

    task: str
    preset: str = "quick"
    seed: int = 0
    epochs: int | None = None  # None: the preset's
    start: str | None = None  # prompt c starts from; None: the null embedding
    prompt: str | None = None  # text feedback (docs/method.md §6)
    prompt_guidance: float = 3.0
    samples: int | None = None  # fresh co-designed samples; None: the preset's
    kappa: float | None = None  # override Table 5's kappa (0: the ablation)
    gamma: float | None = None  # override Table 5's gamma
    n_steps: int = N_STEPS
    prompt_t_min: int = PROMPT_T_MIN  # the prompt guides the steps with t >= this (0: all)
    samples_per_epoch: int | None = None  # designs per embedding epoch; None: the preset's
    sample_steps: int | None = None  # denoising steps per design; None: the preset's
    prior: int | None = None  # shipped prior version; None: the default (recorded at start)
    refine: int | None = None  # refinement steps of the best design; None: the preset's
    signal: float | None = None  # least score spread an epoch trains on; None: the preset's

    @classmethod
    def saved(cls, d: dict) -> Settings:
        """The settings a run's checkpoint recorded, as that run used them: runs from before
        the prompt window had the prompt on every step, runs from before the prior option
        sampled version 1, runs from before co-design from the elite drew the quick
        preset's two fresh samples and refined nothing, and runs from before "no signal, no
        step" trained the embedding on every epoch."""
        if "refine" not in d:
            d = {**d, "refine": 0, "samples": d.get("samples") or
                 (2 if d.get("preset", "quick") == "quick" else None)}
        return cls(**{"prompt_t_min": 0, "prior": 1, "signal": 0.0, **d})

    def check(self) -> None:
        """Refuse settings no run can use (:class:`~dbtool.errors.InputError`, one line),
        before anything is loaded or written."""
        from dbtool.inputs import MAX_STEPS, check_count, check_finite, check_seed, check_text

        check_seed(self.seed)
        check_count("steps", self.n_steps, 1, MAX_STEPS)
        for name, value in (("prompt", self.prompt), ("start", self.start)):
            if value is not None:
                check_text(f"--{name}", value)
        check_finite("--prompt-guidance", self.prompt_guidance)
        if self.refine is not None:
            check_count("--refine", self.refine, 0, 100_000)
        if self.kappa is not None:
            check_finite("--kappa", self.kappa, low=0.0)
        if self.gamma is not None:
            check_finite("gamma", self.gamma, low=0.0)

    def configs(self) -> tuple[EmbeddingConfig, CodesignConfig]:
        self.check()
        if self.preset not in PRESETS:
            raise InputError(f"unknown preset {self.preset!r}; choose one of {', '.join(PRESETS)}")
        emb, cod = preset(self.preset, self.task)
        if self.epochs is not None:
            emb = replace(emb, epochs=self.epochs)
        if self.samples_per_epoch is not None:  # the buffer keeps as many epochs as before
            s = self.samples_per_epoch
            emb = replace(emb, samples_per_epoch=s, min_buffer=min(emb.min_buffer, s),
                          buffer_size=s * max(1, emb.buffer_size // emb.samples_per_epoch),
                          top_k=min(emb.top_k, s), batch_size=min(emb.batch_size, s))
        if self.sample_steps is not None:
            emb = replace(emb, sample_steps=self.sample_steps)
        if self.signal is not None:
            emb = replace(emb, signal=self.signal)
        if self.refine is not None:
            paper = TABLE5[self.task]
            cod = replace(cod, refine=self.refine, refine_gamma=paper.gamma * n_steps(paper)
                          / max(1, self.refine))
        if self.kappa is not None:
            cod = replace(cod, kappa=self.kappa)
        if self.gamma is not None:
            cod = replace(cod, gamma=self.gamma)
        return emb, cod
