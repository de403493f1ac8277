"""Named pattern sets and their measured accuracy: the fastest set for a stated accuracy (issue 51 Deliver 2).

Each :class:`Preset` is a pattern method with its options, given relative to the projector's size so that it fits
any projector; :data:`MEASURED` holds, for each, what one view of it measured against the simulator's exact truth
(``benchmarks/coded/frames_vs_accuracy.py``, the commit in :data:`MEASURED_AT`): the points' RMS and 95th
percentile (mm) and the completeness on the default object (``lumpy``) and the zoo's concave ``bowl`` and
``thin`` objects, on the default simulated rig (1280x1024 camera, 1280x800 projector). docs/coded-light.md
("Frames against accuracy") shows the table.

:func:`fastest_for` picks the preset of fewest frames whose *worst* RMS over those objects is at most the target:
``rangekit scan --target-mm 0.05``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from rangekit.coded.patterns import PatternSpec, make_pattern_spec
from rangekit.errors import OptionError

__all__ = ["Preset", "PRESETS", "MEASURED", "MEASURED_AT", "MEASURED_OBJECTS", "preset_spec", "fastest_for",
           "preset_of"]


@dataclass(frozen=True)
class Preset:
    """A pattern set: ``method`` (:data:`rangekit.coded.patterns.PATTERN_METHODS`), its options, and for ``phase``
    the periods as divisors of each axis's size (``(1, 8, 64)``: periods W, W/8, W/64 for columns, H, H/8, H/64
    for rows); ``what`` says it in words."""

    method: str
    what: str
    options: dict = field(default_factory=dict, hash=False, compare=False)
    period_divisors: tuple[float, ...] | None = None

    def spec(self, projector_size: tuple[int, int]) -> PatternSpec:
        """The :class:`PatternSpec` of this set on a projector of ``(width, height)`` pixels."""
        options = dict(self.options)
        if self.period_divisors is not None:
            w, h = int(projector_size[0]), int(projector_size[1])
            options["periods"] = {"columns": [w / d for d in self.period_divisors],
                                  "rows": [h / d for d in self.period_divisors]}
        return make_pattern_spec(self.method, projector_size, **options)


#: The named pattern sets ``rangekit scan --patterns`` takes besides the bare methods, fewest frames last.
#: ``hybrid-8step-min3`` is the scan's default (:class:`rangekit.app.scan.options.ScanOptions`; issue 51: the fewest
#: frames that keep the 60-frame hybrid's accuracy with a motion check, docs/coded-light.md).
PRESETS: dict[str, Preset] = {
    "hybrid-8step": Preset("hybrid", "Gray code + 8 steps of a 16 px period (the method's own options): 60 frames",
                           {"steps": 8, "period": 16}),
    "hybrid-4step": Preset("hybrid", "Gray code + 4 steps of a 16 px period: 52 frames", {"steps": 4, "period": 16}),
    "hybrid-8step-min3": Preset("hybrid", "Gray code without its 3 finest bits (8 px blocks) + 8 steps of a 16 px "
                                "period: 48 frames", {"steps": 8, "period": 16, "min_bit": 3}),
    "hybrid-4step-min3": Preset("hybrid", "Gray code without its 3 finest bits + 4 steps of a 16 px period: 40 frames",
                                {"steps": 4, "period": 16, "min_bit": 3}),
    "phase-3f": Preset("phase", "three frequencies W, W/8, W/64, 4 + 4 + 8 steps (the method's own options): "
                       "34 frames", {"steps": 4, "fine_steps": 8}, (1, 8, 64)),
    "phase-3f-16px": Preset("phase", "three frequencies W, W/10, W/80 (16 px on the 1280 px projector's columns, "
                            "as hybrid's), 4 + 4 + 8 steps: 34 frames", {"steps": 4, "fine_steps": 8}, (1, 10, 80)),
    "phase-3f-16px-3step": Preset("phase", "three frequencies W, W/10, W/80, 3 + 3 + 8 steps: 30 frames",
                                  {"steps": 3, "fine_steps": 8}, (1, 10, 80)),
    "phase-3f-16px-6step": Preset("phase", "three frequencies W, W/10, W/80, 3 + 3 + 6 steps: 26 frames",
                                  {"steps": 3, "fine_steps": 6}, (1, 10, 80)),
    "phase-3f-4step": Preset("phase", "three frequencies W, W/8, W/64, 4 steps each: 26 frames",
                             {"steps": 4, "fine_steps": 4}, (1, 8, 64)),
    "phase-3f-3step": Preset("phase", "three frequencies W, W/8, W/64, 3 steps each: 20 frames",
                             {"steps": 3, "fine_steps": 3}, (1, 8, 64)),
    "phase-2f": Preset("phase", "two frequencies W, W/16, 4 + 8 steps: 26 frames", {"steps": 4, "fine_steps": 8},
                       (1, 16)),
    "phase-2f-4step": Preset("phase", "two frequencies W, W/16, 4 steps each: 18 frames",
                             {"steps": 4, "fine_steps": 4}, (1, 16)),
}

#: The objects :data:`MEASURED` holds, the default object first.
MEASURED_OBJECTS = ("lumpy", "bowl", "thin")
#: The commit at which :data:`MEASURED` was measured (benchmarks/coded/frames_vs_accuracy.py, seed 1).
MEASURED_AT = "6180cc2"
#: preset -> (frames, {object: (RMS mm, p95 mm, completeness)}), one view against the simulator's truth.
MEASURED: dict[str, tuple[int, dict[str, tuple[float, float, float]]]] = {
    "hybrid-8step": (60, {
        "lumpy": (0.0247, 0.0477, 0.9698),
        "bowl": (0.0304, 0.0599, 0.9442),
        "thin": (0.0294, 0.0574, 0.6810)}),
    "hybrid-4step": (52, {
        "lumpy": (0.0348, 0.0672, 0.9694),
        "bowl": (0.0422, 0.0827, 0.9437),
        "thin": (0.0404, 0.0785, 0.6811)}),
    "hybrid-8step-min3": (48, {
        "lumpy": (0.0247, 0.0477, 0.9700),
        "bowl": (0.0304, 0.0599, 0.9445),
        "thin": (0.0294, 0.0574, 0.6820)}),
    "hybrid-4step-min3": (40, {
        "lumpy": (0.0348, 0.0672, 0.9696),
        "bowl": (0.0422, 0.0827, 0.9441),
        "thin": (0.0404, 0.0785, 0.6823)}),
    "phase-3f": (34, {
        "lumpy": (0.0294, 0.0571, 0.9693),
        "bowl": (0.0361, 0.0710, 0.9440),
        "thin": (0.0342, 0.0669, 0.6817)}),
    "phase-3f-16px": (34, {
        "lumpy": (0.0242, 0.0470, 0.9694),
        "bowl": (0.0298, 0.0587, 0.9436),
        "thin": (0.0285, 0.0556, 0.6814)}),
    "phase-3f-16px-3step": (30, {
        "lumpy": (0.0237, 0.0462, 0.9670),
        "bowl": (0.0296, 0.0584, 0.9415),
        "thin": (0.0294, 0.0571, 0.6794)}),
    "phase-3f-16px-6step": (26, {
        "lumpy": (0.0273, 0.0532, 0.9669),
        "bowl": (0.0338, 0.0670, 0.9413),
        "thin": (0.0329, 0.0650, 0.6799)}),
    "phase-3f-4step": (26, {
        "lumpy": (0.0415, 0.0802, 0.9690),
        "bowl": (0.0501, 0.0991, 0.9435),
        "thin": (0.0471, 0.0932, 0.6815)}),
    "phase-3f-3step": (20, {
        "lumpy": (0.0752, 0.1400, 0.9649),
        "bowl": (0.0902, 0.1716, 0.9397),
        "thin": (0.0864, 0.1660, 0.6802)}),
    "phase-2f": (26, {
        "lumpy": (0.1112, 0.2169, 0.9654),
        "bowl": (0.1346, 0.2664, 0.9399),
        "thin": (0.1256, 0.2479, 0.6712)}),
    "phase-2f-4step": (18, {
        "lumpy": (0.1499, 0.2973, 0.9559),
        "bowl": (0.1873, 0.3745, 0.9335),
        "thin": (0.1770, 0.3512, 0.6683)}),
}


def preset_spec(name: str, projector_size: tuple[int, int]) -> PatternSpec:
    """The spec of preset ``name`` on a ``(width, height)`` projector; OptionError naming the known ones."""
    if name not in PRESETS:
        raise OptionError(f"{{patterns}}: unknown pattern preset {name!r}; known: {', '.join(PRESETS)}")
    return PRESETS[name].spec(projector_size)


def preset_of(spec: PatternSpec) -> str | None:
    """The preset whose spec equals ``spec`` (method, size, axes and options), or None."""
    size = (spec.width, spec.height)
    for name in PRESETS:
        s = PRESETS[name].spec(size)
        if s.axes == spec.axes and s.to_dict() == spec.to_dict():
            return name
    return None


def fastest_for(target_mm: float) -> str:
    """The preset of fewest frames whose worst measured RMS over :data:`MEASURED_OBJECTS` is at most ``target_mm``
    (ties: the lower RMS); OptionError naming the best measured RMS when none meets it."""
    ok = [(frames, max(r[0] for r in per.values()), name) for name, (frames, per) in MEASURED.items()
          if name in PRESETS and max(r[0] for r in per.values()) <= target_mm]
    if not ok and MEASURED:
        best = min((max(r[0] for r in per.values()), name) for name, (frames, per) in MEASURED.items())
        raise OptionError(f"{{target_mm}}: no pattern set measured {target_mm:g} mm RMS or better on one view "
                          f"({', '.join(MEASURED_OBJECTS)}); the best is {best[1]!r} at {best[0]:.4f} mm: "
                          "ask for at least that")
    if not ok:
        raise OptionError("{target_mm}: no pattern set has been measured (rangekit.app.scan.presets.MEASURED is empty)")
    return min(ok)[2]
