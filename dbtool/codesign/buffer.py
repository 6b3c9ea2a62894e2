"""The design buffer of embedding optimisation (Algorithm 1, Table 4).

Every epoch's sampled designs (their x_0 clouds) enter with their performance; the buffer is a
FIFO of ``capacity`` entries, so it holds only the most recent designs (Table 4: for crawling,
gripping and moving a box the buffer is exactly one epoch of samples). The training set is the
``top_k`` entries by performance: the top-k filter is the importance weighting of appendix B
(it concentrates the data on high performance, like the elite set of the cross-entropy
method).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Entry:
    cloud: np.ndarray  # (N, 3), prior frame
    metric: float
    epoch: int


@dataclass
class Buffer:
    capacity: int
    entries: list[Entry] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.entries)

    def add(self, clouds: np.ndarray, metrics: np.ndarray, epoch: int) -> None:
        """Append a batch (oldest entries leave once ``capacity`` is exceeded)."""
        if len(clouds) != len(metrics):
            raise ValueError("clouds and metrics must have the same length")
        for c, m in zip(clouds, metrics, strict=True):
            if np.isfinite(m):
                self.entries.append(Entry(np.asarray(c, np.float32), float(m), epoch))
        self.entries = self.entries[-self.capacity:]

    def training_set(self, top_k: int) -> list[Entry]:
        """The ``top_k`` entries by metric, best first: the elite of the most recent designs
        (the buffer is a FIFO, so old designs leave it)."""
        return self.best(top_k)

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
        if not self.entries:
            return {"clouds": np.zeros((0, 0, 3), np.float32), "metrics": np.zeros(0),
                    "epochs": np.zeros(0, int)}
        return {"clouds": np.stack([e.cloud for e in self.entries]),
                "metrics": np.array([e.metric for e in self.entries]),
                "epochs": np.array([e.epoch for e in self.entries])}

    @classmethod
    def from_state(cls, capacity: int, state: dict) -> Buffer:
        buf = cls(capacity)
        buf.entries = [Entry(c, float(m), int(ep)) for c, m, ep in
                       zip(state["clouds"], state["metrics"], state["epochs"], strict=True)]
        return buf
