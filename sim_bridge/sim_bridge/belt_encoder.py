"""The conveyor drive's encoder (no ROS): what a real drive tells of its belt. It counts the
belt's travel in whole counts of ``resolution`` and reads its speed as the counts over each
reading's period, with the drive's noise (seeded: a lock-step run reads the same every time).
The simulator publishes it with the robots' states, on ``/conveyor/joint_states``."""
from __future__ import annotations

import math
import random
from typing import Optional, Tuple

from world_description.graph_names import BELT_ENCODER_TOPIC
from world_description.world_schema import BeltEncoderConfig

# The encoder's joint, as its JointState names it: position the belt's travel [m], velocity its
# speed [m/s].
BELT_JOINT = 'belt'
ENCODER_TOPIC = BELT_ENCODER_TOPIC


class BeltEncoder:
    def __init__(self, config: BeltEncoderConfig, seed: int) -> None:
        self.config = config
        self._rng = random.Random(f'belt encoder {seed}')
        self._last: Optional[Tuple[float, float]] = None        # (time, travel) last read

    def read(self, time: float, travel: float) -> Tuple[float, float]:
        """The travel [m, whole counts] and the speed [m/s] the encoder reads at ``time``
        [s], the belt having travelled ``travel`` [m] since the world began."""
        res = self.config.resolution
        position = math.floor(travel / res + 1e-9) * res
        last, self._last = self._last, (time, position)
        speed = 0.0
        if last is not None and time > last[0]:
            speed = (position - last[1]) / (time - last[0])
        if self.config.noise > 0.0:
            speed += self._rng.gauss(0.0, self.config.noise)
        return position, speed
