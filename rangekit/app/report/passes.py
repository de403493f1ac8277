"""The report's section of a multi-pass scan: which pass each part of the surface came from.

The merged cloud is drawn coloured by pass (pass 1 dark, the last pass light, the ``turbo`` map) from the
front, the back and below the table (the bottom, which only the turned-over pass sees), with each pass's
share of the points.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rangekit.app.report.figures import crop, figure

__all__ = ["PASS_SIDES", "passes_section"]

#: (azimuth, elevation, name) of the pass figures, radians: front, back, and from below the table.
PASS_SIDES = [(0.0, np.radians(25.0), "front"), (np.pi, np.radians(25.0), "back"),
              (0.0, np.radians(-70.0), "from below")]


def passes_section(view_passes: Sequence[int] | None, clouds: Sequence, merged, frame_pts: np.ndarray,
                   up: np.ndarray, size: tuple[int, int]) -> list[str]:
    """HTML of the section (empty for a single pass). ``clouds``: each view's cloud (only its length is
    used: ``merged`` holds the views' points in view order, session world); ``frame_pts`` the points the
    figures frame (the mesh's vertices)."""
    if not view_passes or max(view_passes) == 0:
        return []
    from rangekit.rendering.snapshot import fit_camera, render_cloud

    n_passes = max(view_passes) + 1
    pass_id = np.concatenate([np.full(len(c), p, dtype=np.float64) for c, p in zip(clouds, view_passes)])
    step = max(1, len(merged) // 600_000)
    figs = [figure(crop(render_cloud(merged.points[::step],
                                     fit_camera(frame_pts, azimuth=az, elevation=el, size=size, up=up, tight=True),
                                     values=pass_id[::step], vmin=0, vmax=n_passes - 1)), f"{name}: colour = pass")
            for az, el, name in PASS_SIDES]
    shares = ", ".join(f"pass {p + 1}: {np.mean(pass_id == p):.0%} of the points" for p in range(n_passes))
    return ["<h2>Passes</h2>", f"<p>{n_passes} turntable passes, the object turned over between them; each pass "
            f"registered from its turntable angles, the passes to each other without a prior. {shares}.</p>",
            f"<div class='row'>{''.join(figs)}</div>"]
