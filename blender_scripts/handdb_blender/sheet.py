"""Colour-mapped label images and contact sheets (numpy + OpenCV, no bpy)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

# BGR colours per link id: background dark grey, palm light; each finger its own hue, darkening
# from the base link to the tip so the phalanges read apart.
_FINGER_HUES = [(40, 140, 255), (60, 200, 60), (230, 120, 40), (200, 60, 200), (40, 200, 230)]


def link_palette() -> np.ndarray:
    pal = np.zeros((256, 3), dtype=np.uint8)
    pal[0] = (40, 40, 40)
    pal[1] = (200, 200, 200)
    for f, hue in enumerate(_FINGER_HUES):
        for k in range(3):
            scale = 1.0 - 0.28 * k
            pal[2 + 3 * f + k] = tuple(int(c * scale) for c in hue)
    return pal


def colourise(labels: np.ndarray) -> np.ndarray:
    return link_palette()[labels]


def contact_sheet(tiles: Sequence[np.ndarray], names: Sequence[str], columns: int,
                  caption_px: int = 28) -> np.ndarray:
    import cv2

    h, w = tiles[0].shape[:2]
    rows = (len(tiles) + columns - 1) // columns
    sheet = np.full((rows * (h + caption_px), columns * w, 3), 255, dtype=np.uint8)
    for i, (tile, name) in enumerate(zip(tiles, names)):
        r, c = divmod(i, columns)
        y, x = r * (h + caption_px), c * w
        sheet[y:y + h, x:x + w] = tile
        size, _ = cv2.getTextSize(name, cv2.FONT_HERSHEY_SIMPLEX, 0.6, 1)
        cv2.putText(sheet, name, (x + (w - size[0]) // 2, y + h + caption_px - 9),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    return sheet
