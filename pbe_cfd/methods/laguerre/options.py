"""The Laguerre ROM's own ``[method]`` keys (``scene.method.options`` of a Laguerre scene)."""
from dataclasses import dataclass


@dataclass(frozen=True)
class LaguerreOptions:
    """Bivariate Laguerre ROM: order m (m x m wet moments), the moment-consistent or plain
    projection, the gamma weights weight_mean_mass [kg], weight_mean_binder [kg] and their
    shapes [-], the quadrature support support_mass [kg], support_binder [kg] on grid_mass x
    grid_binder points, the dry class of granules without binder (its weight
    dry_weight_mean_mass [kg] and shape, dry_grid_mass points), adaptive wet weights and the
    following support, and the closure of the rows of aggregation and droplet capture
    (number_closure: the tensors, or the classes' point measures; docs/physics.md section
    9.2)."""
    order: int = 3
    consistent: bool = True
    weight_mean_mass: float = 1.0e-9
    weight_mean_binder: float = 1.0e-9
    # the wet class's gamma weights vanish at p = 0 and b = 0 (shape 2): with the Laguerre dry
    # class holding every granule at b = 0, a wet granule carries at least one droplet
    weight_shape_mass: float = 2.0
    weight_shape_binder: float = 2.0
    support_mass: float = 1.0e-8
    support_binder: float = 4.0e-9
    grid_mass: int = 20
    grid_binder: int = 20
    grid_spacing: str = "fraction"
    dry_class: bool = True
    dry_weight_mean_mass: float | None = None     # kg; None: the initial mean mass
    dry_weight_shape_mass: float = 10.0           # 2 with following_support
    dry_grid_mass: int = 200
    adaptive_weights: bool = True
    adaptive_points: int = 9
    following_support: bool = False               # the support follows the wet class
    following_growth: float = 1000.0              # its range: up to this x the initial mean mass
    following_shape: bool = True                  # the weight's shape follows the variance
    # the rows of aggregation and droplet capture: "tensor", "points" (order <= 2 on the
    # point measures) or "points-all" (every wet row on them) (unset: with the following
    # support "points-all" for order 3, "points" above; "tensor" with the fixed one;
    # docs/physics.md 9.2)
    number_closure: str | None = None
