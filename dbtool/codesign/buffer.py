"""The design buffer of embedding optimisation (Algorithm 1, Table 4).

Every epoch's sampled designs (their x_0 clouds) enter with their performance; the buffer is a
FIFO of ``capacity`` entries. The training set is the ``top_k`` entries by performance plus
the newest epoch's samples: the top-k filter is the importance weighting of appendix B (it
concentrates the data on high performance), the newest samples keep c anchored near what it
currently generates.
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
        """The top-k entries by metric plus every entry of the newest epoch (no duplicates),
        best first."""
        if not self.entries:
            return []
        order = sorted(range(len(self.entries)), key=lambda i: -self.entries[i].metric)
        newest = max(e.epoch for e in self.entries)
        keep = set(order[:top_k]) | {i for i, e in enumerate(self.entries) if e.epoch == newest}
        return [self.entries[i] for i in order if i in keep]

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
