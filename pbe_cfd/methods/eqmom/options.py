"""The EQMOM's own ``[method]`` keys (``scene.method.options`` of an EQMOM scene)."""
from dataclasses import dataclass


@dataclass(frozen=True)
class EqmomOptions:
    """Gamma EQMOM: the number of gamma kernels N in granule mass (1 to 5; the state carries
    the mass moments M00 .. M(2N)0)."""
    nodes: int = 2
