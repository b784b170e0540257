"""Type names for the numeric arguments of the cores."""
from __future__ import annotations

from typing import Sequence, Union

import numpy as np

# A vector of floats as callers hold it: a list or tuple, or a 1-D numpy array.
Vector = Union[Sequence[float], np.ndarray]
