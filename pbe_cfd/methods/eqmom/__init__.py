"""Extended quadrature method of moments (EQMOM; Yuan, Laurent and Fox 2012) in granule mass
with gamma kernels, or lognormal ones (``[method] kernel = "lognormal"``; Madadi-Kandjani and
Passalacqua 2015), binder per kernel (docs/physics.md, section "EQMOM").

``inversion``: the N-kernel fit to M00 .. M(2N)0 and its fallbacks; ``state``: the state and
work layouts, the binder fractions per kernel and the secondary particles; ``sources``: the
moment sources and the integrator hooks; ``entry``: the method's registry entry and its size
distribution; ``options``: its ``[method]`` keys.
"""
from .entry import ENTRY  # noqa: F401
from .options import EqmomOptions  # noqa: F401
