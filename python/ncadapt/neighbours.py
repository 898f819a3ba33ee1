"""Pairs of points closer than a distance, refused before they are listed when there are too
many to hold in memory."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .errors import InputError

#: Most pairs listed at once (about 60 bytes each in the filters and weights that use them: 6 GB).
MAX_PAIRS = 100_000_000


def pairs_within(tree: cKDTree, r: float, what: str) -> np.ndarray:
    """(m, 2) indices i < j of the points of ``tree`` at most ``r`` apart; ``what`` names the
    distance in the message when there would be more than :data:`MAX_PAIRS` of them."""
    # counting walks the tree without listing: ordered pairs, each point with itself included
    m = (int(tree.count_neighbors(tree, r)) - tree.n) // 2
    if m > MAX_PAIRS:
        raise InputError(
            f"{what} {r:g} mm joins {m:,} pairs of the {tree.n:,} points, more than {MAX_PAIRS:,}; "
            "give a smaller distance"
        )
    return tree.query_pairs(r, output_type="ndarray")
