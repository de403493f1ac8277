"""How close a simulated calibration must come to the simulator's true rig: the tolerances of
tests/calib/test_calibration.py (``rangekit calibrate`` on the simulator), shared with the web app's Calibrate
test, so both are held to the same figures. Keys are those of :func:`rangekit.calib.procedure.compare_rigs`."""

from __future__ import annotations

#: (key path in compare_rigs' dict, largest allowed absolute value, unit)
TOLERANCES = (
    (("camera", "fx"), 0.2, "%"), (("camera", "fy"), 0.2, "%"), (("camera", "cx"), 0.2, "%"), (("camera", "cy"), 0.2, "%"),
    (("projector", "fx"), 0.3, "%"), (("projector", "fy"), 0.3, "%"), (("projector", "cx"), 0.3, "%"),
    (("projector", "cy"), 0.3, "%"),
    (("camera", "dist_diff", 0), 0.002, "k1"), (("projector", "dist_diff", 0), 0.002, "k1"),
    (("baseline_pct",), 0.1, "%"), (("rotation_deg",), 0.02, "deg"),
    (("axis_direction_deg",), 0.05, "deg"), (("axis_point_mm",), 0.2, "mm"), (("table_origin_mm",), 0.5, "mm"),
    (("gamma",), 0.02, ""),
)


def outside_tolerances(dev: dict) -> list[str]:
    """Each deviation of ``dev`` (compare_rigs' dict) beyond its tolerance, one line each; [] when all hold."""
    bad = []
    for path, limit, unit in TOLERANCES:
        value = dev
        for key in path:
            value = value[key]
        if not abs(value) <= limit:
            bad.append(f"{'.'.join(map(str, path))} {value:+.4g} {unit} beyond {limit} {unit}")
    return bad
