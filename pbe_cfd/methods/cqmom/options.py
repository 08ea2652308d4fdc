"""The CQMOM's own ``[method]`` keys (``scene.method.options`` of a CQMOM scene)."""
from dataclasses import dataclass


@dataclass(frozen=True)
class CqmomOptions:
    """CQMOM: the size nodes N1 in granule mass and the binder-fraction nodes N2 conditional
    on each size node."""
    nodes: int = 2
    binder_nodes: int = 2
