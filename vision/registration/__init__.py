"""Feature-based image registration (chapter section 3.3.1): descriptor matching with the
ratio test and mutual check, robust homography/affine verification, and a registration score
in [0, 1] that recognition thresholds (see :mod:`vision.registration.register`)."""

from vision.registration.matching import (
    FLANN_MIN_PRODUCT,
    MATCH_METHODS,
    Matches,
    Neighbours,
    check_compatible,
    match,
    nearest_neighbours,
)
from vision.registration.register import N_SAT, Registration, register, registration_score
from vision.registration.verify import MODELS, ROBUST_METHODS, Verification, verify

__all__ = [
    "FLANN_MIN_PRODUCT",
    "MATCH_METHODS",
    "MODELS",
    "N_SAT",
    "ROBUST_METHODS",
    "Matches",
    "Neighbours",
    "Registration",
    "Verification",
    "check_compatible",
    "match",
    "nearest_neighbours",
    "register",
    "registration_score",
    "verify",
]
