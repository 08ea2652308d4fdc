"""The Laguerre ROM's own ``[method]`` keys (``scene.method.options`` of a Laguerre scene)."""
from dataclasses import asdict, dataclass

#: the fixed support's bounds in p and b when a scene sets none [kg]: seed 000's table III
SEED_SUPPORT_MASS = 1.0e-8
SEED_SUPPORT_BINDER = 4.0e-9
#: the order at which the support follows the wet class unless the scene says otherwise:
#: measured there (docs/results/laguerre.md, "The following support by default"); it needs
#: W20 (m >= 3), and at m = 4 on the seed scenario from a dry start it misses M33 by 36%
#: where the fixed support misses it by 16%
FOLLOWING_ORDER = 3


@dataclass(frozen=True)
class LaguerreOptions:
    """Bivariate Laguerre ROM: order m (m x m wet moments), the moment-consistent or plain
    projection, the gamma weights weight_mean_mass [kg], weight_mean_binder [kg] and their
    shapes [-], the quadrature support support_mass [kg], support_binder [kg] on grid_mass x
    grid_binder points, the dry class of granules without binder (its weight
    dry_weight_mean_mass [kg] and shape, dry_grid_mass points), adaptive wet weights and the
    following support, and the closure of the rows of aggregation and droplet capture
    (number_closure: the tensors, or the classes' point measures; docs/physics.md section
    9.2).

    The support's keys, left unset (None), take their values from each other: ``follows`` is
    following_support, or, unset, true at order 3 unless support_mass or support_binder is
    set (a scene that names a support gets it; ``FOLLOWING_ORDER``);
    ``mass_support`` and ``binder_support`` [kg] are the set bounds or seed 000's."""
    order: int = 3
    consistent: bool = True
    weight_mean_mass: float = 1.0e-9
    weight_mean_binder: float = 1.0e-9
    # the wet class's gamma weights vanish at p = 0 and b = 0 (shape 2): with the Laguerre dry
    # class holding every granule at b = 0, a wet granule carries at least one droplet
    weight_shape_mass: float = 2.0
    weight_shape_binder: float = 2.0
    support_mass: float | None = None             # unset: 1e-8 (seed 000), fixed support
    support_binder: float | None = None           # unset: 4e-9 (seed 000), fixed support
    grid_mass: int = 20
    grid_binder: int = 20
    grid_spacing: str = "fraction"
    dry_class: bool = True
    dry_weight_mean_mass: float | None = None     # kg; None: the initial mean mass
    # the dry class's shape: narrow, at the primary particles (docs/results/laguerre.md)
    dry_weight_shape_mass: float = 10.0
    dry_grid_mass: int = 200
    adaptive_weights: bool = True
    adaptive_points: int = 9
    following_support: bool | None = None         # unset: true if m = 3 and no support_* set
    # the following grid's range: up to this x the initial mean mass (1e6: a batch's granules
    # grow ~2e4-fold in 30 min, the hard cells next to packing up to 5e5-fold in 0.2 s,
    # docs/results/laguerre.md; the tables cost 1.6x the build time of 1e3's, 8 MB)
    following_growth: float = 1.0e6
    following_shape: bool = True                  # the weight's shape follows the variance
    # the rows of aggregation and droplet capture: "tensor", "points" (order <= 2 on the
    # point measures) or "points-all" (every wet row on them) (unset: "points-all" with the
    # following support, "tensor" with the fixed one; docs/physics.md 9.2)
    number_closure: str | None = None

    @property
    def follows(self) -> bool:
        """True if the wet class's weight and support follow it (docs/physics.md 9.2)."""
        if self.following_support is not None:
            return bool(self.following_support)
        return (self.order == FOLLOWING_ORDER and self.support_mass is None
                and self.support_binder is None)

    @property
    def mass_support(self) -> float:
        """The fixed support's bound in p [kg] (the dry class's with the following support)."""
        return SEED_SUPPORT_MASS if self.support_mass is None else float(self.support_mass)

    @property
    def binder_support(self) -> float:
        """The fixed support's bound in b [kg] (not used by the following support)."""
        return SEED_SUPPORT_BINDER if self.support_binder is None else float(self.support_binder)

    def in_effect(self) -> dict:
        """The keys as plain data with the values in effect for the unset ones (summary.json)."""
        return asdict(self) | {"following_support": self.follows,
                               "support_mass": self.mass_support,
                               "support_binder": self.binder_support}
