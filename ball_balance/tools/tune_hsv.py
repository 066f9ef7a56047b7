"""Tune the ball's HSV band on a recorded frame, without a display.

    python -m ball_balance.tools.tune_hsv frame.png --out /tmp/hsv [--lower 0 100 60 --upper 25 255 255]
    python -m ball_balance.tools.tune_hsv frame.png --out /tmp/hsv --pick 412 193

Writes <out>/mask.png (the thresholded, opened mask), <out>/overlay.png (the frame with the
mask tinted and the chosen blob circled) and prints what was found. With `--pick U V` (a
pixel on the ball) it suggests a band from the colours around that pixel and prints it as
YAML lines for config/ball_tracker.yaml.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional, Tuple

import cv2
import numpy as np

from ball_balance.vision.ball_segmentation import BallBlob, BallSegmenter
from ball_balance.vision.config import TRACKER_SCHEMA

DEFAULTS = {p.name: p.default for p in TRACKER_SCHEMA}


def suggest_band(image_bgr: np.ndarray, u: int, v: int, radius_px: int = 6) -> Tuple[Tuple[int, ...], Tuple[int, ...]]:
    """An HSV band around the colours of a small disc at (u, v): hue +-(spread + 4), S and V
    from 60 % of their low percentile up to 255."""
    hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
    disc = np.zeros(hsv.shape[:2], np.uint8)
    cv2.circle(disc, (u, v), radius_px, 255, -1)
    h, s, val = (hsv[..., i][disc > 0].astype(float) for i in range(3))
    h_lo, h_hi = np.percentile(h, 5), np.percentile(h, 95)
    lower = (int(max(h_lo - 4, 0)), int(0.6 * np.percentile(s, 5)), int(0.6 * np.percentile(val, 5)))
    upper = (int(min(h_hi + 4, 179)), 255, 255)
    return lower, upper


def preview(image_bgr: np.ndarray, lower, upper, out_dir: Path, kernel_px: int = 3,
            min_circularity: float = 0.6) -> Optional[BallBlob]:
    """Threshold the whole frame, write mask.png and overlay.png, return the best blob."""
    segmenter = BallSegmenter(lower, upper, kernel_px, min_circularity)
    blob = segmenter.find(image_bgr)
    mask = segmenter.mask
    out_dir.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out_dir / "mask.png"), mask)
    overlay = image_bgr.copy()
    overlay[mask > 0] = (0.5 * overlay[mask > 0] + (0, 127, 0)).astype(np.uint8)
    if blob is not None:
        cv2.circle(overlay, (int(round(blob.u)), int(round(blob.v))), int(round(blob.radius_px)), (0, 0, 255), 1)
    cv2.imwrite(str(out_dir / "overlay.png"), overlay)
    return blob


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("image", help="a recorded frame (PNG/JPEG)")
    parser.add_argument("--out", required=True, help="directory for mask.png and overlay.png")
    parser.add_argument("--lower", type=int, nargs=3, default=DEFAULTS["hsv_lower"], metavar=("H", "S", "V"))
    parser.add_argument("--upper", type=int, nargs=3, default=DEFAULTS["hsv_upper"], metavar=("H", "S", "V"))
    parser.add_argument("--pick", type=int, nargs=2, metavar=("U", "V"), help="a pixel on the ball: suggest a band")
    args = parser.parse_args(argv)
    image = cv2.imread(args.image)
    if image is None:
        print(f"tune_hsv: cannot read image '{args.image}'", file=sys.stderr)
        return 2
    lower, upper = tuple(args.lower), tuple(args.upper)
    if args.pick:
        lower, upper = suggest_band(image, *args.pick)
        print("suggested band (config/ball_tracker.yaml):")
        print(f"    hsv_lower: {list(lower)}\n    hsv_upper: {list(upper)}")
    blob = preview(image, lower, upper, Path(args.out), DEFAULTS["morph_kernel_px"], DEFAULTS["min_circularity"])
    coverage = 100.0 * np.count_nonzero(cv2.imread(str(Path(args.out) / "mask.png"), 0)) / image[..., 0].size
    if blob is None:
        print(f"band {list(lower)}..{list(upper)}: {coverage:.2f} % of pixels, no round blob found")
        return 1
    print(f"band {list(lower)}..{list(upper)}: {coverage:.2f} % of pixels; ball at ({blob.u:.2f}, {blob.v:.2f}) px, "
          f"radius {blob.radius_px:.1f} px, circularity {blob.circularity:.2f}; previews in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
