"""The ``dbtool design TASK`` command's run (the design *run*; the :class:`dbtool.design.Design`
record it ends with lives in ``dbtool/design.py``): embedding optimisation (docs/method.md §4),
then diffusion as co-design (§5), then the final robot, all in a resumable run directory.

Files of a run (each written atomically: temp file, then rename)::

    config.json      resolved settings and both configs (Tables 4-5 after the preset)
    manifest.json    provenance (commit, config hash, time, machine, versions), seed, device
    metrics.jsonl    one row per epoch and per co-design Langevin step
    checkpoint.pt    state after the last completed epoch / Langevin stop of a co-designed sample
    best.npz         the best designs of all embedding epochs (clouds, metrics)
    trajectory.npz   each co-designed sample's x_t and x0-estimate at every Langevin stop
    design.npz       the final robot (upsampled cloud, fields, controller, metric)
    performance.png  performance per epoch and along co-design
    montage.png      the final robot in motion

``--resume`` reloads ``checkpoint.pt`` and continues from the last completed unit of work;
everything in it is restored (embedding, Adam state, random generator, buffer, finished
co-design samples, the chain of the unfinished one), so a resumed run repeats the uninterrupted
one.
"""

from __future__ import annotations

import io
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from dbtool.atomic import atomic_write, atomic_write_text
from dbtool.codesign.config import PROMPT_T_MIN, CodesignConfig, Settings
from dbtool.codesign.embedding import EmbeddingOptimiser, score
from dbtool.codesign.langevin import ChainState, codesign_sample
from dbtool.codesign.refine import RefineConfig, RefineState, refine
from dbtool.errors import InputError, RunError
from dbtool.sim.tasks import N_STEPS, Task, get_task

FORMAT = "dbtool.run/1"
CHECKPOINT = "checkpoint.pt"


class RunDirectoryError(InputError):
    """A run directory or its checkpoint cannot be used."""


def guidance_terms(prior, c: torch.Tensor, guidance: float, prompt: str | None = None,
                   prompt_guidance: float = 3.0, prompt_t_min: int = PROMPT_T_MIN
                   ) -> list[tuple]:
    """Guidance terms of the co-design chain: the embedding ``c`` at ``guidance``, plus the
    text-feedback ``prompt`` at its own weight, guiding the steps with ``t >= prompt_t_min``
    only (docs/method.md §6)."""
    conds: list[tuple] = [(c, guidance)]
    if prompt:
        conds.append((prior.embed(prompt), prompt_guidance, prompt_t_min))
    return conds


def codesign_design(prior, task: Task, conds: list[tuple], cfg: CodesignConfig, seed: int,
                    steps: int, n_steps: int = N_STEPS, on_step=None, on_stop=None,
                    resume: ChainState | None = None) -> dict:
    """One design of diffusion as co-design (docs/method.md §5) and its score:
    ``{"cloud", "metric", "controller", "stop", "trajectory"}``. The final sample is scored
    forward with its co-optimised controller (NaN where it cannot be robotized or simulated); with
    ``cfg.handover == "best"`` the best design the chain simulated replaces it when it scored
    higher, and ``stop`` is the timestep that made it (None: the final sample). ``on_stop`` and
    ``resume``: see :func:`~dbtool.codesign.langevin.codesign_sample`."""
    res = codesign_sample(prior, task, conds, cfg, seed=seed, steps=steps, n_steps=n_steps,
                          on_step=on_step, on_stop=on_stop, resume=resume)
    metric = float(score(res.cloud[None], task, n_steps, controllers=[res.controller])[0])
    out = {"cloud": res.cloud, "metric": metric, "controller": res.controller, "stop": None}
    b = res.best
    if cfg.handover == "best" and b is not None and not metric >= b.metric:
        out = {"cloud": b.cloud, "metric": b.metric, "controller": b.controller, "stop": b.t}
    out["trajectory"] = trajectory_arrays(res.trajectory)
    return out


def trajectory_arrays(stops: list) -> dict[str, np.ndarray]:
    """A chain's co-design trajectory (:class:`~dbtool.codesign.langevin.Stop` list) as
    arrays: ``t`` (S,), ``xt`` and ``x0`` (S, N, 3), float32."""
    n = len(stops[0].xt) if stops else 0
    return {"t": np.array([s.t for s in stops], np.int64),
            "xt": np.array([s.xt for s in stops], np.float32).reshape(len(stops), n, 3),
            "x0": np.array([s.x0 for s in stops], np.float32).reshape(len(stops), n, 3)}


@dataclass
class State:
    """Everything a checkpoint holds."""

    epoch: int = 0
    rows: list[dict] = field(default_factory=list)
    samples: list[dict] = field(default_factory=list)  # finished co-design samples
    partial: ChainState | None = None  # the unfinished sample's chain after its last stop
    refine: RefineState | None = None  # the unfinished refinement after its last step


class Paused(Exception):  # noqa: N818 - not an error: the run stopped where it was asked to
    """Raised inside :meth:`DesignRun.run` after the requested Langevin stops."""


def _savez(path: Path, **arrays) -> Path:
    def save(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)

    return atomic_write(path, save)


class DesignRun:
    """A run directory and the optimiser state behind it."""

    def __init__(self, path: str | Path, settings: Settings, prior=None, scorer=None) -> None:
        self.path = Path(path)
        self.folder = None  # the locked run folder (start, resume) until close
        self.settings = settings
        self.task = get_task(settings.task)
        self.emb_cfg, self.cod_cfg = settings.configs()
        if prior is None:
            from dbtool.prior.sampling.pipeline import DEFAULT_VERSION, Prior

            settings.prior = settings.prior or DEFAULT_VERSION
            prior = Prior.load(version=settings.prior)
        self.prior = prior
        start = prior.embed(settings.start) if settings.start else prior.null()
        self.opt = EmbeddingOptimiser(prior, self.task, self.emb_cfg, start, seed=settings.seed,
                                      n_steps=settings.n_steps, scorer=scorer)
        self.state = State()

    # ------------------------------------------------------------------ files
    def config(self) -> dict:
        """Settings, both configs, and the prior's guidance interval (from its weights folder,
        docs/method.md §1; ``None``: guidance on every step)."""
        gi = getattr(self.prior, "guidance_interval", None)
        return {"command": "design", "method": "diffusebot", "settings": asdict(self.settings),
                "embedding": asdict(self.emb_cfg), "codesign": asdict(self.cod_cfg),
                "prior_guidance_interval": list(gi) if gi else None}

    def start(self, device: str) -> None:
        """Create and lock the run directory: a new or empty folder, or a design run that
        saved no work (no checkpoint, no design); anything else is refused before writing."""
        from dbtool.runs import RunFolder, manifest, write_json

        self._check_new(self.path)
        self.folder = RunFolder(self.path, "design")
        try:
            self._check_new(self.path)  # again, under the lock
            write_json(self.path / "config.json", self.config())
            write_json(self.path / "manifest.json", manifest(self.settings.seed, device,
                                                             self.config(), "design"))
            self._write_metrics()
        except BaseException:
            self.folder.abandon()
            raise

    @staticmethod
    def _check_new(path: Path) -> None:
        from dbtool.runs import check_run_dir

        if (path / CHECKPOINT).exists() or (path / "design.npz").exists():
            raise RunDirectoryError(f"{path} already holds a run; continue it with --resume or "
                                    "give another --out")
        check_run_dir(path, "design")

    def saved_work(self) -> bool:
        """Whether the run directory holds a checkpoint (``--resume`` can continue it)."""
        return (self.path / CHECKPOINT).is_file()

    def close(self, ok: bool = True) -> None:
        """Unlock the run directory. ``ok=False`` (the run failed or was interrupted): a run
        that saved no checkpoint leaves nothing behind (what it wrote is removed)."""
        folder = getattr(self, "folder", None)
        if folder is None:
            return
        if ok or self.saved_work():
            folder.release()
        else:
            folder.abandon()
        self.folder = None

    def log(self, **row) -> None:
        self.state.rows.append(row)
        self._write_metrics()

    def _write_metrics(self) -> None:
        text = "".join(json.dumps(r) + "\n" for r in self.state.rows)
        atomic_write_text(self.path / "metrics.jsonl", text)

    def checkpoint(self) -> None:
        o = self.opt
        buf = o.buffer.state()
        ck = {"format": FORMAT, "settings": asdict(self.settings), "epoch": self.state.epoch,
              "embedding": o.embedding.state_dict(), "adam": o.opt.state_dict(),
              "generator": o.gen.get_state(), "history": json.dumps(o.history),
              "buffer": {k: torch.as_tensor(v) for k, v in buf.items()},
              "rows": json.dumps(self.state.rows), "samples": [
                  {"cloud": torch.as_tensor(s["cloud"]), "metric": s["metric"],
                   "stop": -1 if s.get("stop") is None else int(s["stop"]),
                   "controller": None if s["controller"] is None
                   else torch.as_tensor(s["controller"]),
                   **({"refined": s["refined"]} if "refined" in s else {}),
                   **({"trajectory": {k: torch.as_tensor(v) for k, v in s["trajectory"].items()}}
                      if s.get("trajectory") else {})} for s in self.state.samples],
              "partial": None if self.state.partial is None else self.state.partial.to_dict(),
              "refine": None if self.state.refine is None else self.state.refine.to_dict()}

        def save(tmp: str) -> None:
            bio = io.BytesIO()
            torch.save(ck, bio)
            Path(tmp).write_bytes(bio.getvalue())

        atomic_write(self.path / CHECKPOINT, save)

    @classmethod
    def resume(cls, path: str | Path, prior=None, scorer=None) -> DesignRun:
        """Reload a run directory from its checkpoint."""
        path = Path(path)
        ck_path = path / CHECKPOINT
        if not path.is_dir() or not (path / "config.json").is_file():
            raise RunDirectoryError(f"{path} is not a dbtool run directory (no config.json)")
        if not ck_path.is_file():
            raise RunDirectoryError(f"{path} has no checkpoint to resume from ({CHECKPOINT})")
        try:
            ck = torch.load(ck_path, map_location="cpu", weights_only=True)
            if not isinstance(ck, dict) or ck.get("format") != FORMAT:
                raise RunDirectoryError(f"{ck_path} is not a dbtool run checkpoint")
            run = cls(path, Settings.saved(ck["settings"]), prior, scorer)
            o = run.opt
            o.embedding.load_state_dict(ck["embedding"])
            o.opt.load_state_dict(ck["adam"])
            o.gen.set_state(ck["generator"])
            o.history = json.loads(ck["history"])
            o.epoch = int(ck["epoch"])
            from dbtool.codesign.buffer import Buffer

            o.buffer = Buffer.from_state(run.emb_cfg.buffer_size,
                                         {k: v.numpy() for k, v in ck["buffer"].items()})
            run.state = State(int(ck["epoch"]), json.loads(ck["rows"]), [
                {"cloud": s["cloud"].numpy(), "metric": float(s["metric"]),
                 "stop": None if int(s.get("stop", -1)) < 0 else int(s["stop"]),
                 "controller": None if s["controller"] is None else s["controller"].numpy(),
                 **({"refined": str(s["refined"])} if "refined" in s else {}),
                 **({"trajectory": {k: v.numpy() for k, v in s["trajectory"].items()}}
                    if "trajectory" in s else {})}
                for s in ck["samples"]])
            if ck.get("partial") is not None:
                run.state.partial = ChainState.from_dict(ck["partial"])
            if ck.get("refine") is not None:
                run.state.refine = RefineState.from_dict(ck["refine"])
        except RunDirectoryError:
            raise
        except Exception as exc:  # noqa: BLE001 - any damage gets the same one-line error
            raise RunDirectoryError(f"corrupt checkpoint {ck_path} ({exc.__class__.__name__}: "
                                    f"{str(exc)[:80]})") from None
        from dbtool.runs import RunFolder

        # the checkpoint shows the folder is a design run: lock it while the run continues
        run.folder = RunFolder(path, "design", option="--out", check=False)
        return run

    # ------------------------------------------------------------------ work
    def conds(self) -> list[tuple]:
        """Guidance terms of the co-design chain (:func:`guidance_terms`) from the optimised
        embedding and the settings' prompt."""
        s = self.settings
        return guidance_terms(self.prior, self.opt.current(), self.emb_cfg.guidance, s.prompt,
                              s.prompt_guidance, s.prompt_t_min)

    def run(self, show_progress: bool = True, report: bool = True,
            pause_after_stops: int | None = None):
        """Finish the run from wherever it stands; returns the final :class:`Design`
        (``report``: also write ``report.html``, :func:`write_run_report`), or None when
        paused (checkpointed) after ``pause_after_stops`` Langevin stops of this call. The
        directory is unlocked when this returns; a run that stops (an error, Ctrl-C) before
        its first checkpoint leaves nothing behind (:meth:`close`)."""
        try:
            design = self._run(show_progress, report, pause_after_stops)
        except BaseException:
            self.close(ok=False)
            raise
        self.close()
        return design

    def _run(self, show_progress: bool, report: bool, pause_after_stops: int | None):
        from tqdm import tqdm

        stops_left = [pause_after_stops]

        def stop_done(chain: ChainState) -> None:
            self.state.partial = chain
            self.checkpoint()
            if stops_left[0] is not None:
                stops_left[0] -= 1
                if stops_left[0] <= 0:
                    raise Paused

        emb, cod = self.emb_cfg, self.cod_cfg
        with tqdm(total=emb.epochs, initial=self.state.epoch, desc="embedding epochs",
                  unit="epoch", disable=not show_progress or None, leave=False) as bar:
            while self.state.epoch < emb.epochs:
                row = dict(self.opt.step())  # the optimiser's history keeps its own row
                w = self.opt.embedding.weights()
                if w is not None:
                    row["top_weight"] = float(w.max())
                self.state.epoch += 1
                self.log(phase="embedding", **row)
                self._save_best()
                self.checkpoint()
                bar.set_postfix(mean=f"{row['mean']:.4f}", max=f"{row['max']:.4f}")
                bar.update(1)
        n = cod.samples if self.settings.samples is None else self.settings.samples
        conds = self.conds()
        with tqdm(total=n, initial=len(self.state.samples), desc="co-design samples",
                  unit="design", disable=not show_progress or None, leave=False) as bar:
            while len(self.state.samples) < n:
                k = len(self.state.samples)
                seed = self.settings.seed * 1_000_003 + 10_007 * (k + 1)
                try:
                    sample = codesign_design(
                        self.prior, self.task, conds, cod, seed, emb.sample_steps,
                        self.settings.n_steps,
                        on_step=lambda r, k=k: self.log(phase="codesign", sample=k, **r),
                        on_stop=stop_done, resume=self.state.partial)
                except Paused:
                    return None
                self.state.partial = None
                self.state.samples.append(sample)
                self.log(phase="codesign", sample=k, final=True, metric=sample["metric"],
                         stop=sample["stop"])
                self._save_trajectory()
                self.checkpoint()
                bar.update(1)
        if cod.refine > 0 and not any("refined" in s for s in self.state.samples):
            try:
                self._refine(cod, show_progress, stops_left)
            except Paused:
                return None
        return self.finish(report)

    def _candidates(self) -> list[dict]:
        """The designs the run can hand over: its finished samples and the epochs' best."""
        ok = [dict(s, source=source(s)) for s in self.state.samples if np.isfinite(s["metric"])]
        ok += [{"cloud": e.cloud, "metric": e.metric, "controller": None,
                "source": f"embedding epoch {e.epoch}"} for e in self.opt.buffer.elite[:1]]
        return ok

    def _refine(self, cod: CodesignConfig, show_progress: bool, stops_left: list) -> None:
        """Co-design from the elite (docs/method.md §5): the best design so far refined by
        ``cod.refine`` steps at t = 0, checkpointed after each; it joins the samples."""
        from tqdm import tqdm

        cands = self._candidates()
        if not cands:
            return  # nothing to refine (no epoch, no sample): finish says so
        start = max(cands, key=lambda c: c["metric"])
        cfg = RefineConfig(steps=cod.refine, gamma=cod.refine_gamma)

        def step_done(st: RefineState) -> None:
            self.state.refine = st
            self.checkpoint()
            bar.update(1)
            if stops_left[0] is not None:
                stops_left[0] -= 1
                if stops_left[0] <= 0:
                    raise Paused

        done = 0 if self.state.refine is None else self.state.refine.k
        with tqdm(total=cod.refine, initial=done, desc="refinement steps", unit="step",
                  disable=not show_progress or None, leave=False) as bar:
            best = refine(self.task, start["cloud"], start["metric"], cfg,
                          self.settings.n_steps, start["controller"],
                          on_step=lambda r: self.log(phase="refine", **r),
                          on_state=step_done, resume=self.state.refine)
        self.state.refine = None
        self.state.samples.append({"cloud": best["cloud"], "metric": best["metric"],
                                   "controller": best["controller"], "stop": None,
                                   "refined": f"{start['source']}, step {best['step']}"})
        self.log(phase="refine", final=True, metric=best["metric"], step=best["step"])
        self.checkpoint()

    def _save_best(self, n: int = 8) -> None:
        best = self.opt.buffer.elite[:n]
        if best:
            _savez(self.path / "best.npz", clouds=np.stack([e.cloud for e in best]),
                   metrics=np.array([e.metric for e in best]),
                   epochs=np.array([e.epoch for e in best]))

    def _save_trajectory(self) -> None:
        """``trajectory.npz``: the co-designed samples' stops (``sample`` k's rows of ``xt``
        and ``x0``: samples x stops x N x 3) and each sample's final metric."""
        done = [(k, s) for k, s in enumerate(self.state.samples) if s.get("trajectory")
                and len(s["trajectory"]["t"])]
        if done:
            _savez(self.path / "trajectory.npz", t=done[0][1]["trajectory"]["t"],
                   sample=np.array([k for k, _ in done]),
                   metric=np.array([s["metric"] for _, s in done], float),
                   xt=np.stack([s["trajectory"]["xt"] for _, s in done]),
                   x0=np.stack([s["trajectory"]["x0"] for _, s in done]))

    def finish(self, report: bool = True):
        """The run's :class:`Design`, plus the figures (and ``report.html``): the best
        co-designed sample, unless a design of the embedding epochs scored higher
        (``meta["source"]`` says which)."""
        from dbtool.design import Design
        from dbtool.robotize import robotize
        from dbtool.sim.rollout import simulate
        from dbtool.viz.render import montage

        ok = self._candidates()
        if not ok:
            raise RunError("no co-designed sample could be robotized and simulated")
        best = max(ok, key=lambda s: s["metric"])
        robot = robotize(best["cloud"], self.task).robot.compact()
        ctrl = best["controller"] if best["controller"] is not None else \
            self.task.controller(self.settings.n_steps)
        ro = simulate(self.task, robot, ctrl, n_steps=self.settings.n_steps)
        surface = best["cloud"]
        if getattr(self.prior, "upsampler", None) is not None:
            surface = self.prior.upsample(best["cloud"][None], seed=self.settings.seed)[0]
        meta = {"method": "diffusebot", "preset": self.settings.preset,
                "seed": self.settings.seed, "prompt": self.settings.prompt,
                "start": self.settings.start, "epochs": self.state.epoch,
                "samples": [s["metric"] for s in self.state.samples],
                "source": best["source"]}
        design = Design(self.task.name, robot, ctrl, surface, {self.task.name: ro.metric},
                        meta)
        design.save(self.path / "design.npz")
        from dbtool.codesign.run_figures import performance_figure, write_run_report

        performance_figure(self.state.rows, self.path / "performance.png", self.task.title)
        montage(ro.episode, ro.positions, self.path / "montage.png",
                title=f"{self.task.title}: metric {ro.metric:.4f}")
        if report:
            write_run_report(self.path, design, ro, self.state.rows)
        return design


def source(sample: dict) -> str:
    """Which stage made a co-designed sample: its final sample or the stop of the chain, or
    the refinement of the elite (what it started from and the step, -1: none improved)."""
    if "refined" in sample:
        return f"co-design from the elite ({sample['refined']})"
    stop = sample.get("stop")
    return "co-design (final sample)" if stop is None else f"co-design (stop t = {stop})"
