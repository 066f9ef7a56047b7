"""The ball in the image: HSV colour band, morphological opening, best round blob.

Works inside a window (the plate's image region), so only that part of the frame is
converted and thresholded. Returns the blob's sub-pixel centre (first image moments of
its contour) in full-image pixels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import cv2
import numpy as np


@dataclass(frozen=True)
class BallBlob:
    u: float             # centre, pixels (full image)
    v: float
    radius_px: float     # sqrt(area / pi)
    circularity: float   # 4 pi area / perimeter^2, 1 for a disc
    area_px: float
    # bounding box of its contour, full-image pixels (x0, y0, x1, y1), end exclusive
    bbox_px: Optional[Tuple[int, int, int, int]] = None


class BallSegmenter:
    """HSV threshold + opening + contour selection. A lower hue above the upper hue wraps
    around 180 (for red balls)."""

    def __init__(self, hsv_lower: Sequence[int], hsv_upper: Sequence[int], morph_kernel_px: int = 3,
                 min_circularity: float = 0.6):
        self.lower = np.array(hsv_lower, np.uint8)
        self.upper = np.array(hsv_upper, np.uint8)
        self.wraps = int(hsv_lower[0]) > int(hsv_upper[0])
        self.kernel = (cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (morph_kernel_px, morph_kernel_px))
                       if morph_kernel_px > 1 else None)
        self.min_circularity = min_circularity
        self.mask: Optional[np.ndarray] = None   # last mask (window), for debugging and tuning

    def threshold(self, image_bgr: np.ndarray) -> np.ndarray:
        """Binary mask (uint8 0/255) of the colour band, after the opening."""
        hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
        if self.wraps:
            high = self.upper.copy()
            high[0] = 179
            low = self.lower.copy()
            low[0] = 0
            mask = cv2.inRange(hsv, self.lower, high) | cv2.inRange(hsv, low, self.upper)
        else:
            mask = cv2.inRange(hsv, self.lower, self.upper)
        if self.kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self.kernel)
        return mask

    def find(self, image_bgr: np.ndarray, window: Optional[Tuple[int, int, int, int]] = None,
             radius_range_px: Tuple[float, float] = (1.0, 1e9)) -> Optional[BallBlob]:
        """The best blob (largest area x circularity within the radius range), or None."""
        x0, y0, x1, y1 = window or (0, 0, image_bgr.shape[1], image_bgr.shape[0])
        if x1 - x0 < 2 or y1 - y0 < 2:
            return None
        self.mask = mask = self.threshold(image_bgr[y0:y1, x0:x1])
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        best, best_score = None, 0.0
        r_min, r_max = radius_range_px
        for contour in contours:
            moments = cv2.moments(contour)
            # the contour runs through boundary pixel centres: add the half-pixel rim back
            perimeter = cv2.arcLength(contour, True)
            area = moments["m00"] + 0.5 * perimeter
            if area <= 0.0:
                continue
            radius = math.sqrt(area / math.pi)
            if not r_min <= radius <= r_max or moments["m00"] <= 0.0:
                continue
            circularity = 4.0 * math.pi * moments["m00"] / max(perimeter, 1e-9) ** 2
            if circularity < self.min_circularity:
                continue
            score = area * circularity
            if score > best_score:
                u = moments["m10"] / moments["m00"] + x0
                v = moments["m01"] / moments["m00"] + y0
                bx, by, bw, bh = cv2.boundingRect(contour)
                best, best_score = BallBlob(u, v, radius, circularity, area,
                                            (bx + x0, by + y0, bx + x0 + bw, by + y0 + bh)), score
        return best
