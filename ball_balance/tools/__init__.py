"""Command-line helpers for the tracker: camera calibration, HSV band tuning (headless)."""
