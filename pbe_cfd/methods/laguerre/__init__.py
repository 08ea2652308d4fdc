"""Bivariate Laguerre reduced-order model: numba RHS (``rhs``), basis, tensors and their
build, the scene-level entry points (``tensor``) its ``[method]`` keys (``options``) and the registry entry
(``entry``)."""
from .entry import ENTRY, laguerre_state_names  # noqa: F401
from .options import LaguerreOptions  # noqa: F401
from .rhs import (laguerre_conserved, laguerre_project, laguerre_realizable,  # noqa: F401
                  laguerre_rhs)
