"""Read-only float arrays: the array fields of rss6's immutable descriptions (scene, trajectory,
realised robot), which numpy would otherwise let a caller change in place."""
from __future__ import annotations

import numpy as np


def frozen_array(values) -> np.ndarray:
    """``values`` as a new float array that cannot be written to."""
    out = np.array(values, dtype=float)
    out.flags.writeable = False
    return out
