"""A relation set's row and column scales over every multiplier row (each rank holds its own
rows' and its ghosts'): for checks of small systems against the whole matrix."""

import numpy as np


def whole_scales(rset) -> tuple[np.ndarray, np.ndarray]:
    """(row scales, column scales) of every multiplier row, from their owners. Collective."""
    dm = rset.dofmap
    _, _, l0, l1 = dm.owned()
    out = np.zeros((2, dm.nl))
    out[0, l0:l1], out[1, l0:l1] = rset.row_scale[:l1 - l0], rset.col_scale[:l1 - l0]
    return tuple(dm.sum_ranks(out))
