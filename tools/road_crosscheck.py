#!/usr/bin/env python3
"""MPD of road profiles by captif-slp, the published ISO 13473-1:2019 implementation of
CAPTIF (NZ Transport Agency), for the cross-check of Tangent's own (`docs/road.md`,
"Cross-check").

Usage: road_crosscheck.py PROFILE.csv [...]

Each CSV has a header `distance_mm,relative_height_mm` and one row per raw sample
(positions from the segment start, ascending; an empty or `nan` height is a drop-out).
Prints one JSON object: {path: {"mpd_mm": float or null, "valid": bool, "msd_mm": [...]}}.
Exit code 3 (with the reason on stderr) when captif-slp is not installed.

The settings are the ones Tangent uses: 100 mm segments, 0.5 mm resampling, spike threshold
alpha = 3 (captif-slp's `Reading.from_trace` default), no evaluation length (spot
measurement: slope suppression per segment, no high-pass).
"""
import json
import sys

try:
    import numpy as np
    import pandas as pd
    from captif_slp.slp import Reading
except ImportError as e:  # pragma: no cover - the caller skips with this reason
    print(f"captif-slp is not installed ({e}); `pip install captif-slp`", file=sys.stderr)
    sys.exit(3)


def mpd_of(path):
    trace = pd.read_csv(path)
    trace["relative_height_mm"] = pd.to_numeric(trace["relative_height_mm"], errors="coerce")
    reading = Reading.from_trace(
        trace,
        segment_length_mm=100,
        target_sample_spacing_mm=0.5,
        alpha=3,
    )
    segments = reading.msd()
    result = reading.mpd()
    mpd = result["mpd"]
    return {
        "mpd_mm": None if mpd is None or np.isnan(mpd) else float(mpd),
        "valid": bool(result["is_valid"]),
        "msd_mm": [float(s["msd"]) for s in segments],
    }


def main(paths):
    print(json.dumps({p: mpd_of(p) for p in paths}))


if __name__ == "__main__":
    main(sys.argv[1:])
