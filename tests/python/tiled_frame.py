"""A frame dict made larger by tiling it: a native call long enough for another thread or a
signal to arrive while it runs."""

from __future__ import annotations

import numpy as np


def tiled_frame(frame: dict, tiles: int) -> dict:
    """`frame` (as affinity_core.read_frame gives it) tiled `tiles` x `tiles` times, without a reference."""
    return {
        **frame,
        "samples": np.ascontiguousarray(np.tile(frame["samples"], (tiles, tiles, 1, 1))),
        "motion": np.ascontiguousarray(np.tile(frame["motion"], (tiles, tiles, 1))),
        "valid": np.ascontiguousarray(np.tile(frame["valid"], (tiles, tiles))),
        "reference": None,
    }
