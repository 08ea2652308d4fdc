"""The EQMOM's own ``[method]`` keys (``scene.method.options`` of an EQMOM scene)."""
from dataclasses import dataclass


#: the kernel families of ``[method] kernel``
KERNELS = ("gamma", "lognormal")


@dataclass(frozen=True)
class EqmomOptions:
    """EQMOM: the number of kernels N in granule mass (1 to 5; the state carries the mass
    moments M00 .. M(2N)0) and their family, "gamma" (default) or "lognormal"."""
    nodes: int = 2
    kernel: str = "gamma"    # the kernels: gamma or lognormal in granule mass (physics.md 16)
