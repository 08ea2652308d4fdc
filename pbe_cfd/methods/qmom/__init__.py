"""Quadrature method of moments with node-wise binder: the numba functions (``qmom``) its ``[method]``
keys (``options``) and the registry entry (``entry``)."""
from .entry import ENTRY  # noqa: F401
from .options import QmomOptions  # noqa: F401
from .qmom import (qmom_conserved, qmom_on_closure, qmom_project,  # noqa: F401
                   qmom_realizable, qmom_rhs,
                   quadrature_of, state_names, work_size)
