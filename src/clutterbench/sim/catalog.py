"""Box catalogues (thesis 4.2.1, Fig. 4.3 / 4.7): same-size, various-size, held-out "new".

Sizes are written as the thesis writes them, H x W x D in millimetres. A box lying flat has
its height along world z, its width along y and its depth along x; its local extents are
therefore (D, W, H).
"""

from __future__ import annotations

import numpy as np

from clutterbench.errors import ClutterbenchError

# (H, W, D) mm.
CATALOGUES: dict[str, tuple[tuple[float, float, float], ...]] = {
    # thesis 4.2.1: one type, H20 x W100 x D100 mm.
    "same": ((20, 100, 100),),
    # thesis 4.2.1 / SPEC: five rectangular types spanning H27-40 x W85-130 x D80-160 mm.
    "various": ((27, 85, 80), (30, 100, 120), (34, 115, 100), (37, 130, 140), (40, 95, 160)),
    # Held out for generalisation (thesis 4.3.3 "new objects", Table 4.1): sizes that no
    # training catalogue holds, inside the same overall range.
    "new": ((29, 120, 90), (33, 90, 150), (36, 105, 110), (39, 125, 85), (31, 110, 130)),
}


def box_extents_m(name: str) -> np.ndarray:
    """(types, 3) local extents (D, W, H) in metres of catalogue `name`."""
    if name not in CATALOGUES:
        raise ClutterbenchError(f"unknown box catalogue '{name}' (known: {', '.join(CATALOGUES)})")
    hwd = np.array(CATALOGUES[name], dtype=np.float64) / 1000.0
    return hwd[:, [2, 1, 0]]
