"""Boxes resting on the pulled box's top, or leaning on its side, fall (no network)."""

import numpy as np


def predict(depth_m, masks, camera_K, pulled):
    """depth_m (H, W) metres, masks (K, H, W) bool of the visible boxes, camera_K (3, 3), the
    pulled box's position among them -> (K,) probability that pulling it collapses each box."""
    rows, cols = np.nonzero(masks[pulled])
    top, left, right = rows.min(), cols.min(), cols.max()
    z = np.median(depth_m[masks[pulled]])
    out = np.zeros(len(masks))
    for k, m in enumerate(masks):
        if k == pulled:
            continue
        r, c = np.nonzero(m)
        overlap = max(0, min(right, c.max()) - max(left, c.min())) / max(1, c.max() - c.min())
        above = r.max() <= top + 2  # its bottom edge at or above the pulled box's top
        near = abs(np.median(depth_m[m]) - z) < 0.05  # about as deep: in the same row
        touching = abs(r.mean() - rows.mean()) < (rows.max() - top) and overlap == 0
        if above and near:
            out[k] = 0.3 + 0.6 * overlap  # resting on it: the more it overlaps, the likelier
        elif touching and near:
            out[k] = 0.25  # beside it: may lean on it
        else:
            out[k] = 0.05
    return out
