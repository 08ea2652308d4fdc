"""The QMOM's own ``[method]`` keys (``scene.method.options`` of a QMOM scene)."""
from dataclasses import dataclass


@dataclass(frozen=True)
class QmomOptions:
    """QMOM: the number of quadrature nodes in granule mass (1 to 5; the state carries
    the 2 N mass moments M00 .. M(2N-1)0)."""
    nodes: int = 3
