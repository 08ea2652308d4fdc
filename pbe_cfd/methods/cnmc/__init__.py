"""Constant-number Monte Carlo reference: the ensemble run (``ensemble``), its numba box
(``box``, ``slots``, ``breakage``) its ``[method]`` keys (``options``) and the registry entry
(``entry``)."""
from .entry import ENTRY  # noqa: F401
from .options import CnmcOptions  # noqa: F401
