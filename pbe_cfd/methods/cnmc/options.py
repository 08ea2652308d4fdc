"""The cNMC reference's own ``[method]`` keys (``scene.method.options`` of a cNMC scene)."""
from dataclasses import dataclass


@dataclass(frozen=True)
class CnmcOptions:
    """Constant-number Monte Carlo: particles per replica, independent replicas, and the
    seed of the first replica's random stream."""
    particles: int = 10000
    replicas: int = 8
    seed: int = 1
