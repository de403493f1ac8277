"""The names of ``rangekit.registration.coarse``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .align import (CoarseOptions as CoarseOptions, Features as Features, coarse_align as coarse_align,
    coarse_align_seeds as coarse_align_seeds, compute_features as compute_features)
