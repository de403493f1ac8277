"""Registration of range scans: ICP, GPA, synchronisation, coarse alignment, multi-view (Fusiello ch. 14-15)."""

from rangekit.registration.bearings import BearingLocation, Localisability, localisability, locate_from_bearings
from rangekit.registration.coarse import CoarseOptions, Features, coarse_align, compute_features
from rangekit.registration.gpa import GPAResult, gpa
from rangekit.registration.icp import KERNELS, IcpOptions, OrganisedScan, RegistrationResult, icp
from rangekit.registration.multiview import (EdgeResult, JointResult, MultiViewOptions, MultiViewResult, overlap_rms,
                                             pairwise_overlap, refine_jointly, register_views)
from rangekit.registration.sync import (RotationSync, SyncResult, TranslationSync, synchronise, synchronise_rotations,
                                        synchronise_translations)

__all__ = ["BearingLocation", "Localisability", "localisability", "locate_from_bearings", "CoarseOptions", "Features", "coarse_align", "compute_features", "GPAResult", "gpa", "KERNELS",
           "IcpOptions", "OrganisedScan", "RegistrationResult", "icp", "EdgeResult", "JointResult",
           "MultiViewOptions", "MultiViewResult", "overlap_rms", "pairwise_overlap", "refine_jointly",
           "register_views", "RotationSync", "SyncResult", "TranslationSync", "synchronise",
           "synchronise_rotations", "synchronise_translations"]
