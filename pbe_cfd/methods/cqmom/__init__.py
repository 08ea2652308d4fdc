"""Conditional quadrature method of moments for granule mass and binder: layout and inversion
(``cqmom``), conditional quadrature (``conditional``), sources (``sources``), its ``[method]``
keys (``options``) and the registry entry (``entry``)."""
from .cqmom import (cqmom_conserved, cqmom_project, cqmom_realizable,  # noqa: F401
                    quadrature_of, state_names, work_size)
from .entry import ENTRY  # noqa: F401
from .options import CqmomOptions  # noqa: F401
from .sources import cqmom_rhs  # noqa: F401
