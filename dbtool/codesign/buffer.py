"""The design buffer of embedding optimisation (Algorithm 1, Table 4).

Every epoch's sampled designs (their x_0 clouds) enter with their performance; the buffer is a
FIFO of ``capacity`` entries, so it holds only the most recent designs (Table 4: for crawling,
gripping and moving a box the buffer is exactly one epoch of samples). The training set is the
``top_k`` entries by performance: the top-k filter is the importance weighting of appendix B
(it concentrates the data on high performance, like the elite set of the cross-entropy
method).

Separately from the FIFO, the buffer remembers the ``keep`` best designs ever seen (``elite``),
so a run can hand over a design that worked in an early epoch. With ``elite=True`` the training
set is the top-k of the FIFO and the elite together (an option, off in both presets: measured
in docs/codesign-archive.md, it did not help).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Entry:
    cloud: np.ndarray  # (N, 3), prior frame
    metric: float
    epoch: int
    atom: int = -1  # the mixture atom it was sampled from (-1: not a mixture design)


def _same(a: Entry, b: Entry) -> bool:
    """One design (a checkpoint restores the FIFO and the elite as separate copies)."""
    return (a is b or (a.epoch == b.epoch and a.metric == b.metric and a.atom == b.atom
                       and np.array_equal(a.cloud, b.cloud)))


@dataclass
class Buffer:
    capacity: int
    entries: list[Entry] = field(default_factory=list)
    elite: list[Entry] = field(default_factory=list)  # the best designs ever added
    keep: int = 8

    def __len__(self) -> int:
        return len(self.entries)

    def add(self, clouds: np.ndarray, metrics: np.ndarray, epoch: int,
            atoms: np.ndarray | None = None) -> None:
        """Append a batch (oldest entries leave once ``capacity`` is exceeded)."""
        if len(clouds) != len(metrics):
            raise ValueError("clouds and metrics must have the same length")
        atoms = np.full(len(metrics), -1) if atoms is None else np.asarray(atoms)
        new = [Entry(np.asarray(c, np.float32), float(m), epoch, int(a))
               for c, m, a in zip(clouds, metrics, atoms, strict=True) if np.isfinite(m)]
        self.entries = (self.entries + new)[-self.capacity:]
        self.elite = sorted(self.elite + new, key=lambda e: -e.metric)[:self.keep]

    def spread(self) -> float:
        """How far apart the buffer's scores are (best minus worst; 0 when empty): the
        signal a training step has to rank designs by.

        >>> b = Buffer(4); b.add(np.zeros((2, 3, 3)), np.array([0.5, 0.25]), epoch=0)
        >>> b.spread()
        0.25
        """
        m = [e.metric for e in self.entries]
        return max(m) - min(m) if m else 0.0

    def training_set(self, top_k: int, elite: bool = False) -> list[Entry]:
        """The ``top_k`` entries by metric, best first: the best of the most recent designs
        (the buffer is a FIFO, so old designs leave it), or with ``elite`` the best of those
        and of the best designs ever seen."""
        if not elite:
            return self.best(top_k)
        pool = list(self.entries)
        pool += [e for e in self.elite if not any(_same(e, f) for f in self.entries)]
        return sorted(pool, key=lambda e: -e.metric)[:top_k]

    def newest(self) -> list[Entry]:
        """The newest epoch's entries (unfiltered)."""
        if not self.entries:
            return []
        last = max(e.epoch for e in self.entries)
        return [e for e in self.entries if e.epoch == last]

    def best(self, n: int = 1) -> list[Entry]:
        return sorted(self.entries, key=lambda e: -e.metric)[:n]

    def state(self) -> dict:
        """Arrays for a checkpoint (``np.savez``)."""
        out = {}
        for prefix, entries in (("", self.entries), ("elite_", self.elite)):
            if not entries:
                out.update({f"{prefix}clouds": np.zeros((0, 0, 3), np.float32),
                            f"{prefix}metrics": np.zeros(0), f"{prefix}epochs": np.zeros(0, int),
                            f"{prefix}atoms": np.zeros(0, int)})
                continue
            out.update({f"{prefix}clouds": np.stack([e.cloud for e in entries]),
                        f"{prefix}metrics": np.array([e.metric for e in entries]),
                        f"{prefix}epochs": np.array([e.epoch for e in entries]),
                        f"{prefix}atoms": np.array([e.atom for e in entries])})
        return out

    @classmethod
    def from_state(cls, capacity: int, state: dict) -> Buffer:
        buf = cls(capacity)
        for prefix in ("", "elite_"):
            if f"{prefix}clouds" not in state:  # checkpoints before the elite was kept
                continue
            n = len(state[f"{prefix}metrics"])
            atoms = state.get(f"{prefix}atoms", np.full(n, -1))  # older checkpoints: none
            entries = [Entry(c, float(m), int(ep), int(a)) for c, m, ep, a in
                       zip(state[f"{prefix}clouds"], state[f"{prefix}metrics"],
                           state[f"{prefix}epochs"], atoms, strict=True)]
            setattr(buf, "elite" if prefix else "entries", entries)
        return buf
