"""The names of ``rangekit.registration``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .bearings import (BearingLocation as BearingLocation, Localisability as Localisability,
    localisability as localisability, locate_from_bearings as locate_from_bearings)
from .coarse import (CoarseOptions as CoarseOptions, Features as Features, coarse_align as coarse_align,
    compute_features as compute_features)
from .gpa import GPAResult as GPAResult, gpa as gpa
from .icp import (KERNELS as KERNELS, IcpOptions as IcpOptions, OrganisedScan as OrganisedScan,
    RegistrationResult as RegistrationResult, icp as icp)
from .multiview import (EdgeResult as EdgeResult, JointResult as JointResult, MultiViewOptions as MultiViewOptions,
    MultiViewResult as MultiViewResult, overlap_rms as overlap_rms, pairwise_overlap as pairwise_overlap,
    refine_jointly as refine_jointly, register_views as register_views)
from .sync import (RotationSync as RotationSync, SyncResult as SyncResult, TranslationSync as TranslationSync,
    synchronise as synchronise, synchronise_rotations as synchronise_rotations,
    synchronise_translations as synchronise_translations)
