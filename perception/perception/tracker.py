"""Tracking materials across frames: one stable id per physical material while it crosses the
view, so that a consumer counts each material once and never picks one twice."""
from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Deque, List, Optional, Sequence, Tuple

import numpy as np


@dataclass
class Sighting:
    """A material seen in one frame: its colour class and where the frame puts it."""
    color: str
    position: np.ndarray         # world, metres
    u: float
    v: float
    confidence: float


@dataclass
class Track:
    id: int
    # About 4 s at 15 Hz: a long baseline for the velocity, which predicts where to pick.
    history: Deque[Tuple[float, np.ndarray]] = field(default_factory=lambda: deque(maxlen=60))
    votes: Counter[str] = field(default_factory=Counter)
    hits: int = 0
    missed: int = 0
    last: Optional[Sighting] = None
    confidence: float = 0.0
    mean_confidence: float = 0.0

    @property
    def color(self) -> str:
        return str(self.votes.most_common(1)[0][0])

    @property
    def position(self) -> np.ndarray:
        return self.history[-1][1]

    @property
    def stamp(self) -> float:
        return self.history[-1][0]

    def velocity(self) -> np.ndarray:
        """Least-squares velocity over the recent history (zero with one sample)."""
        if len(self.history) < 2:
            return np.zeros(3)
        t = np.array([h[0] for h in self.history])
        p = np.array([h[1] for h in self.history])
        t = t - t.mean()
        denom = float((t * t).sum())
        if denom <= 0.0:
            return np.zeros(3)
        return np.asarray((t[:, None] * (p - p.mean(axis=0))).sum(axis=0) / denom)

    def predict(self, t: float) -> np.ndarray:
        return self.position + self.velocity() * (t - self.stamp)


class Tracker:
    """Greedy nearest-neighbour association within ``gate`` metres of each track's predicted
    position; a track is reported once seen in ``min_hits`` frames and dropped after
    ``max_missed`` frames without a match. Ids are never reused."""

    def __init__(self, gate: float = 0.04, min_hits: int = 3, max_missed: int = 5) -> None:
        if gate <= 0.0 or min_hits < 1 or max_missed < 0:
            raise ValueError('gate must be > 0, min_hits >= 1, max_missed >= 0')
        self.gate, self.min_hits, self.max_missed = gate, min_hits, max_missed
        self.tracks: List[Track] = []
        self.next_id = 1
        self.confirmed_ids: List[int] = []

    def update(self, t: float, observations: Sequence[Sighting]) -> List[Track]:
        """Associate one frame's observations; return the confirmed tracks seen in it."""
        pairs = []
        for ti, track in enumerate(self.tracks):
            predicted = track.predict(t)
            for oi, obs in enumerate(observations):
                d = float(np.linalg.norm((obs.position - predicted)[:2]))
                if d <= self.gate:
                    pairs.append((d, ti, oi))
        used_t, used_o = set(), set()
        for _, ti, oi in sorted(pairs):
            if ti in used_t or oi in used_o:
                continue
            used_t.add(ti)
            used_o.add(oi)
            self._add(self.tracks[ti], t, observations[oi])
        for ti, track in enumerate(self.tracks):
            if ti not in used_t:
                track.missed += 1
        for oi, obs in enumerate(observations):
            if oi not in used_o:
                track = Track(self.next_id)
                self.next_id += 1
                self._add(track, t, obs)
                self.tracks.append(track)
        self.tracks = [tr for tr in self.tracks if tr.missed <= self.max_missed]
        seen = []
        for track in self.tracks:
            if track.missed == 0 and track.hits >= self.min_hits:
                if track.id not in self.confirmed_ids:
                    self.confirmed_ids.append(track.id)
                seen.append(track)
        return seen

    def _add(self, track: Track, t: float, obs: Sighting) -> None:
        track.history.append((t, np.asarray(obs.position, float)))
        track.votes[obs.color] += 1
        track.hits += 1
        track.missed = 0
        track.last = obs
        # Running mean of the per-frame confidences, scaled by the colour vote's agreement.
        track.mean_confidence = (obs.confidence if track.hits == 1 else
                                 0.8 * track.mean_confidence + 0.2 * obs.confidence)
        track.confidence = track.votes[track.color] / track.hits * track.mean_confidence
