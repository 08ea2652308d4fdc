"""Constant-number Monte Carlo reference: the ensemble run (``ensemble``), its numba box
(``box``, ``slots``, ``breakage``) and the registry entry (``entry``)."""
from .entry import ENTRY  # noqa: F401
