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


def stripe_errors(r, method, normalize=True, **kw):
    """The stripe centres' errors against a rendered session's true centres (px), and the same
    over their reported sigma: (errors, z-scores) over every view's found scan lines."""
    import hmlvs

    errs, z = [], []
    for i in range(len(r.on)):
        d = hmlvs.difference_image(r.on[i], r.off[i], normalize=normalize)
        s = hmlvs.extract_stripe(d, method=method, **kw)
        f = s.found & np.isfinite(r.stripe_v[i])
        errs.append(s.centre[f] - r.stripe_v[i][f])
        z.append((s.centre[f] - r.stripe_v[i][f]) / s.sigma[f])
    return np.concatenate(errs), np.concatenate(z)
