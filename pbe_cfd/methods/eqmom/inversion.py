"""EQMOM's gamma-kernel inversion, which lives in ``methods.quadrature.gamma_inversion``
(QMOM and CQMOM draw their size distributions with it too): its public names, for callers of
the EQMOM package."""
from ..quadrature.gamma_inversion import (CLOSEST, DISCRETE, EMPTY, FAILED, FEWER,  # noqa: F401
                                          FIT, REDUCED, STATUS_TEXT, gamma_rule, invert_normalised,
                                          kernel_moment, star_moments, work_length)
