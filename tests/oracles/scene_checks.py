"""Checks of what a rendered view shows, shared by the image tests."""

import numpy as np


def shows_block(px, board, image_size=(640, 480), k=3, margin=25.0):
    """Whether predicted corner pixels hold a whole k x k block of the board at least
    ``margin`` px inside the image: such a view's board must be found (the detector needs a
    3 x 3 grid; the margin keeps borderline views out of the claim)."""
    w, h = image_size
    ok = (np.isfinite(px).all(axis=1) & (px[:, 0] >= margin) & (px[:, 0] <= w - 1 - margin) &
          (px[:, 1] >= margin) & (px[:, 1] <= h - 1 - margin)).reshape(board.rows, board.cols)
    return any(ok[r:r + k, c:c + k].all() for r in range(board.rows - k + 1)
               for c in range(board.cols - k + 1))
