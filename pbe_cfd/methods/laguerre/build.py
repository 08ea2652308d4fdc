"""Laguerre ROM: build the flat ``aux`` array (layout: ``laguerre_layout``) and cache it on disk.

Runs once per scene (or once per cache key) in Python/numpy with numba loops for the kernel
matrices. The kernel matrices depend on the quadrature nodes' masses and the collision velocity
only, so they are evaluated once per slice and reused for every weight of the adaptive grid;
when they are identical at both ends of a Theta grid (the physical efficiency saturated over
the whole range) the grid collapses to one slice.

Adaptive weights: the wet class's gamma weights have the means c = W10/W00 (mean mass) and
d = W01/W00 (mean binder) of the wet class itself, so that the expansion's first-order
coefficients vanish and the basis follows the class as it grows (a fixed weight cannot serve the
first wet granules, one primary particle and a droplet, and the aggregates of 600 s at once).
The tensors are tabulated on a log grid of (c, d) and the RHS blends the four neighbours
bilinearly in (ln c, ln d).

Following support (``adaptive=dict(following=True, ...)``, docs/physics.md section 9.2): the grid
is in (ln c, ln y), y = d / c, and every weight slice integrates over its own support
p <= span c, b <= p, so the support follows the wet class's mean mass over the grid's range of c.
The slices then have their own nodes, and the wet kernel matrices are evaluated per slice.
"""
import hashlib
import json
import math
import os

import numpy as np

from ...physics import parameters as P
from ...physics.injection import droplet_liquid
from ...physics.efficiency import uses_collision_velocity
from ...util.threads import run_shares, run_threads
from .basis import GRADED, SPACINGS
from .breakage import breakage_blocks
from .drying import drying_blocks
from .dry import cross_tensors, dry_class, dry_kernels, dry_tensors, dry_wet_rates
from .layout import (AUX_B_MAX, AUX_CAPTURE_MOMENTS, AUX_CHECK_LEVEL, AUX_COND_DRY,
                     AUX_COND_G, AUX_CONSISTENT, AUX_DROPLET_MASS, AUX_FOLLOWING, AUX_HEADER,
                     AUX_LAYOUT_VERSION,
                     AUX_MASS_SCALE, AUX_N_B, AUX_N_DRY, AUX_N_NODES, AUX_N_P,
                     AUX_NMOM, AUX_NPAIR, AUX_NSLICE, AUX_NWC, AUX_NWD, AUX_NWL, AUX_OFF_BASIS,
                     AUX_OFF_BREAK, AUX_OFF_DRYING,
                     AUX_OFF_CAPMAP, AUX_OFF_CD, AUX_OFF_CD0, AUX_OFF_CDD,
                     AUX_OFF_CONDW, AUX_OFF_DRY_BASIS, AUX_OFF_F43, AUX_OFF_F43D,
                     AUX_OFF_LOGU, AUX_OFF_LOGW, AUX_OFF_Q, AUX_OFF_QDD,
                     AUX_OFF_SUPPORT, AUX_OFF_WET_SUPPORT, AUX_OFF_X, AUX_OFF_XL,
                     AUX_ORDER, AUX_P_MAX, AUX_SEPARATE, AUX_SPACING,
                     AUX_U0_FIXED, AUX_VERSION, TABLE_III)
from .wet import wet_basis, wet_kernels, wet_tensors

_ALGO_TAG = "laguerre-rom-3-dry-class-adaptive"
_SOURCES = ("build.py", "layout.py", "basis.py", "wet.py", "dry.py", "breakage.py", "drying.py")
#: default adaptive grid of the wet weight means: c in [p_max/32, p_max/2.5], d in
#: [b_max/64, b_max/2] (the weight must fit in the support)
ADAPTIVE_RANGES = dict(c=(1.0 / 32.0, 1.0 / 2.5), d=(1.0 / 64.0, 0.5))
#: following support: p_max = FOLLOWING_SPAN c_m of each slice, c_m = W20/W10 the mass-weighted
#: mean mass. The mass of a gamma population of shape k is distributed as a gamma of shape
#: k + 1 and mean c_m: beyond 8 c_m lie Q(2, 16) = 2e-6 of it for k = 1 (exponential) and
#: Q(1.5, 12) = 3e-5 for k = 0.5. Grid points per decade of c_m; the range of the
#: mass-weighted binder fraction y = d / c = W01 / W10 and its points
FOLLOWING_SPAN = 8.0
FOLLOWING_POINTS_PER_DECADE = 3.0
FOLLOWING_RATIO = (0.01, 1.0)
FOLLOWING_RATIO_POINTS = 5
#: a following slice's binder fraction lies on [0, min(1, FRACTION_SPAN y)], y its mean
#: fraction (ours): the default grid's lowest slice (y = 0.01) keeps [0, 1], and a slice of a
#: lower y has the same quadrature in b / y, so its basis is that slice's scaled (the
#: fraction weight's share beyond 100 means is exp(-200) for the scenes' shape 2). On
#: [0, 1] a slice of y = 1e-3 has a singular Gram matrix (cond 3e11; 1e-4: 3e17)
FRACTION_SPAN = 100.0
#: with [drying] the fraction axis gains these points below FOLLOWING_RATIO's, one per
#: decade (ours): the falling-rate period takes the wet class's fraction towards 0, and below
#: the lowest slice the class is evaluated at that slice's fraction (``position.binder_shift``);
#: at 1e-4 the bundled material's geometric factor is within 0.35% and its critical Stokes
#: number within 0.7% of their values at y = 0 (docs/physics.md section 9.2). Each such slice
#: has nodes of its own (its fraction support is 100 y), so each costs the kernel matrices of
#: a whole set of slices: one point per decade, not FOLLOWING_RATIO's two
FOLLOWING_DRYING_BELOW = (1.0e-4, 1.0e-3)
#: the gamma shapes lambda in p of the following weight, one per octave: the weight's shape
#: follows the carried W10^2 / (W00 W20 - W10^2), so that with m = 3 the mass marginal's
#: expansion is the gamma of the carried M0, M1, M2 itself (docs/physics.md section 9.2).
#: 1/32: the batch on the bundled bed reaches a carried shape of 0.06-0.08 at 30 min (and the
#: sum kernel's suite case 0.05), an octave below that is the lowest the graded quadrature
#: (``laguerre_basis.graded_mass_nodes``) is shown to hold: u^(4/3) g to 9e-5 and u^k g,
#: k < 2m, to round-off at 1/32 (tests/methods/laguerre/test_laguerre_graded.py); 8: a
#: narrower weight spans under two of the six uniform cells on [0, 8 c_m] (u^6..u^8 g to
#: 6e-4 there)
FOLLOWING_SHAPES = (1.0 / 32.0, 8.0)


def unit_params(params):
    """params with the kernel rate k0 set to 1 (k0 is applied at RHS time)."""
    q = np.array(params, dtype=np.float64).copy()
    q[P.RATE] = 1.0
    return q


def _needs_u0(config):
    """True if a factor switched on reads the collision velocity (the tensors then depend on
    the cell's Theta and are tabulated on a Theta grid)."""
    return uses_collision_velocity(config)


def _source_digest():
    here = os.path.dirname(os.path.abspath(__file__))
    phys = os.path.join(os.path.dirname(os.path.dirname(here)), "physics")
    h = hashlib.sha256()
    paths = [os.path.join(phys, f) for f in ("kernels.py", "efficiency.py", "rates.py",
                                             "properties.py", "parameters.py", "breakage.py",
                                             "drying.py")]
    paths += [os.path.join(here, f) for f in _SOURCES]
    for path in paths:
        with open(path, "rb") as fh:
            h.update(fh.read())
    return h.hexdigest()


def _cache_key(params, config, order, weights, support, consistent, u0_grid, adaptive):
    q = np.array(params, dtype=np.float64).copy()
    for slot in (P.RATE, P.NUMBER_SCALE, P.STEP_FLOOR):   # factored out / irrelevant
        q[slot] = 0.0
    # every switch the tensors depend on: kernel, droplets, breakage and the whole efficiency
    # block (a factor added to the registry changes the key without an edit here)
    cfg = [int(config[s]) for s in (P.KERNEL, P.SEPARATE_DROPLETS, P.BREAKAGE,
                                    P.BREAKAGE_SELECTION, P.BREAKAGE_DAUGHTERS,
                                    P.DROPLET_LIQUID)]
    cfg += [int(x) for x in config[P.EFFICIENCY_SWITCHES:]]
    blob = json.dumps(dict(tag=_ALGO_TAG, src=_source_digest(), params=q.tolist(), config=cfg,
                           order=int(order),
                           weights={k: float(v) for k, v in weights.items()},
                           support={k: float(support[k]) for k in ("p_max", "b_max", "n_p",
                                                                   "n_b", "n_dry")},
                           spacing=spacing_code(support), consistent=bool(consistent),
                           adaptive=adaptive,
                           u0=None if u0_grid is None else [float(x) for x in u0_grid]),
                      sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def spacing_code(support):
    """Quadrature spacing code of a support dict ("uniform" by default)."""
    sp = support.get("spacing", "uniform")
    if isinstance(sp, str):
        if sp not in SPACINGS:
            raise ValueError(f"support spacing must be one of {sorted(SPACINGS)}, got {sp!r}")
        return SPACINGS[sp]
    return int(sp)


def default_cache_dir():
    """Directory of cached aux arrays: $PBE_CFD_CACHE or ~/.cache/pbe_cfd/laguerre."""
    return os.environ.get("PBE_CFD_CACHE",
                          os.path.join(os.path.expanduser("~"), ".cache", "pbe_cfd", "laguerre"))


def theta_to_u0(theta):
    """Collision velocity u0 = 4 sqrt(Theta / pi) [m/s] from granular temperature [m2/s2]."""
    return 4.0 * np.sqrt(np.asarray(theta, float) / math.pi)


def _u0_grid(config, theta_grid, collision_velocity):
    if not _needs_u0(config):
        return None
    if theta_grid is not None:
        u0_grid = np.sort(theta_to_u0(np.asarray(theta_grid, float)))
        if u0_grid.size < 1 or not np.all(u0_grid > 0):
            raise ValueError("theta_grid must hold positive granular temperatures")
        return u0_grid
    if collision_velocity is not None and collision_velocity > 0:
        return np.array([float(collision_velocity)])
    raise ValueError("physical efficiency on: give theta_grid or collision_velocity")


def _following_spec(spec):
    """dict(following, c=[lo, hi] [kg], y=[lo, hi] [-], points_c, points_y, span [-],
    shapes=[lo, hi] [-] or None (the fixed weight shape), points_l[, y_below]: fractions
    [-] added below y_lo)."""
    c = [float(x) for x in spec["c"]]
    if not (0.0 < c[0] < c[1]):
        raise ValueError(f"following support: need 0 < c_lo < c_hi [kg], got {c}")
    y = [float(x) for x in spec.get("y") or FOLLOWING_RATIO]
    if not (0.0 < y[0] < y[1] <= 1.0):
        raise ValueError(f"following support: need 0 < y_lo < y_hi <= 1, got {y}")
    below = sorted(float(x) for x in spec.get("y_below") or ())
    if below and not (0.0 < below[0] and below[-1] < y[0] and len(set(below)) == len(below)):
        raise ValueError(f"following support: need distinct 0 < y_below < y_lo, got {below}")
    decades = math.log10(c[1] / c[0])
    n_c = int(spec.get("points_c")
              or max(2, math.ceil(decades * FOLLOWING_POINTS_PER_DECADE) + 1))
    n_y = int(spec.get("points_y") or FOLLOWING_RATIO_POINTS)
    span = float(spec.get("span") or FOLLOWING_SPAN)
    if n_c < 2 or n_y < 2 or not span > 1.0:
        raise ValueError("following support: need >= 2 grid points a side and span > 1")
    shapes = spec.get("shapes", FOLLOWING_SHAPES)
    n_l = 1
    if shapes:
        shapes = [float(x) for x in shapes]
        if not (0.0 < shapes[0] < shapes[1]):
            raise ValueError(f"following support: need 0 < shape_lo < shape_hi, got {shapes}")
        n_l = int(spec.get("points_l") or round(math.log2(shapes[1] / shapes[0])) + 1)
    return dict(following=True, c=c, y=y, points_c=n_c, points_y=n_y, span=span,
                shapes=shapes or None, points_l=max(n_l, 2) if shapes else 1,
                **({"y_below": below} if below else {}))


def _adaptive_spec(adaptive, support):
    """None (fixed weights), dict(c=[lo, hi] [kg], d=[lo, hi] [kg], points), or the following
    support's dict (``_following_spec``)."""
    if not adaptive:
        return None
    if adaptive is not True and adaptive.get("following"):
        return _following_spec(adaptive)
    spec = dict(points=9) if adaptive is True else dict(adaptive)
    n = int(spec.get("points", 9))
    if n < 2:
        raise ValueError(f"adaptive weights need at least 2 grid points a side, got {n}")
    c = spec.get("c") or [support["p_max"] * f for f in ADAPTIVE_RANGES["c"]]
    d = spec.get("d") or [support["b_max"] * f for f in ADAPTIVE_RANGES["d"]]
    return dict(c=[float(x) for x in c], d=[float(x) for x in d], points=n)


def build_aux(params, config, order, weights=None, support=None, consistent=True,
              theta_grid=None, cache_dir=None, collision_velocity=None, use_cache=True,
              check_level=0, adaptive=None):
    """Build (or load from the disk cache) the flat float64 ``aux`` array of the Laguerre ROM.

    params, config: the arrays of ``physics.parameters`` (SI). order: m (2, 3 or 4).
    weights: dict(c [kg], d [kg], lam [-], gam [-][, c_dry [kg], lam_dry [-]]) -- gamma
    weights of the wet class, mean c in p, mean d in b; of the dry class, mean c_dry and shape
    lam_dry in p (default c, lam).
    support: dict(p_max [kg], b_max [kg], n_p, n_b[, spacing][, n_dry]) -- integration support,
    grid cells per side and spacing ("uniform" in (p, b), the default and seed 000's choice, or
    "fraction": uniform in p and in the binder fraction b/p, see ``laguerre_basis.quadrature``);
    n_dry: cells in p of the dry class's quadrature on [0, p_max] (default n_p).
    Defaults: seed 000 table III. consistent: moment-consistent reconstruction (default) or the
    seed's plain projection (both classes). adaptive: None/False (fixed weight means c, d),
    True or dict(points=n[, c=(lo, hi) [kg]][, d=(lo, hi) [kg]]): wet weight means following
    the wet class, tensors tabulated on an n x n log grid (module doc). theta_grid: granular
    temperatures [m2/s2] (log-spaced) on which to tabulate the tensors when the physical
    efficiency is on and u0 = 4 sqrt(Theta / pi) comes from the cell; otherwise
    collision_velocity [m/s] fixes u0 (needed iff the physical efficiency is on). The kernel
    rate k0, N_ref and the ktgf factor g0 sqrt(Theta) d43^(3/2) are applied at RHS time, so
    they do not enter the tensors or the cache key. Cached as .npy under cache_dir (default
    ``default_cache_dir()``) keyed by a hash of everything else that determines the tensors,
    including the physics and tensor source code. check_level (0, 1, 2): which moment
    conditions laguerre_realizable enforces (stored in aux, not part of the key).
    """
    weights = dict(TABLE_III["weights"], **(weights or {}))
    support = dict(TABLE_III["support"], **(support or {}))
    m = int(order)
    if m < 1 or m > 6:
        raise ValueError(f"Laguerre order must be 1..6, got {m}")
    weights["c_dry"] = float(weights.get("c_dry") or weights["c"])
    weights["lam_dry"] = float(weights.get("lam_dry") or weights["lam"])
    weights = {k: float(weights[k]) for k in ("c", "d", "lam", "gam", "c_dry", "lam_dry")}
    support["n_dry"] = int(support.get("n_dry") or support["n_p"])
    if (min(weights.values()) <= 0 or min(support["p_max"], support["b_max"]) <= 0
            or min(int(support[k]) for k in ("n_p", "n_b", "n_dry")) < 1):
        raise ValueError("Laguerre weights and support must be positive")
    p_ref = float(params[P.MASS_SCALE])
    if not p_ref > 0:
        raise ValueError("params[MASS_SCALE] must be set (> 0) before build_aux")
    u0_grid = _u0_grid(config, theta_grid, collision_velocity)
    spec = _adaptive_spec(adaptive, support)
    if spec is not None and spec.get("following") and m < 3:
        raise ValueError("the following support needs order >= 3 (it follows W20 / W10)")
    key = _cache_key(params, config, m, weights, support, consistent, u0_grid, spec)
    path = os.path.join(cache_dir or default_cache_dir(), f"aux_{key}.npy")
    if use_cache and os.path.exists(path):
        try:
            aux = np.load(path)
            if aux.dtype == np.float64 and aux[AUX_VERSION] == AUX_LAYOUT_VERSION:
                aux[AUX_CHECK_LEVEL] = check_level
                return aux
        except (OSError, ValueError):
            pass
    grid = dict(p_max=float(support["p_max"]), b_max=float(support["b_max"]),
                n_p=int(support["n_p"]), n_b=int(support["n_b"]), n_dry=support["n_dry"],
                spacing=spacing_code(support))
    aux = _build(params, config, m, weights, grid, consistent, u0_grid, p_ref, spec)
    aux[AUX_CHECK_LEVEL] = check_level
    if use_cache:
        try:
            os.makedirs(os.path.dirname(path), exist_ok=True)
            tmp = f"{path}.{os.getpid()}.tmp.npy"
            np.save(tmp, aux)
            os.replace(tmp, path)
        except OSError:
            pass
    return aux


def _weight_grid(weights, spec):
    """(ln c grid, ln d grid, ln lambda grid, [(c, d, lambda) per weight slice]) of the wet
    weights (means [kg], shape [-]); with the following support the second grid is ln(d / c),
    the first ln c_m (mass-weighted means), and slice w = (il * nwc + ic) * nwd + jd."""
    lam = weights["lam"]
    if spec is not None and spec.get("following"):
        # grid in the mass-weighted mean c_m = W20/W10; the gamma weight of shape lam with
        # that mass-weighted mean has the number mean c = c_m lam / (lam + 1)
        cg = np.geomspace(spec["c"][0], spec["c"][1], spec["points_c"])
        yg = np.concatenate([spec.get("y_below", []),
                             np.geomspace(spec["y"][0], spec["y"][1], spec["points_y"])])
        lg = (np.geomspace(spec["shapes"][0], spec["shapes"][1], spec["points_l"])
              if spec.get("shapes") else np.array([lam]))
        return np.log(cg), np.log(yg), np.log(lg), [
            (cm * sh / (sh + 1.0), y * cm * sh / (sh + 1.0), sh)
            for sh in lg for cm in cg for y in yg]
    if spec is None:
        cg, dg = np.array([weights["c"]]), np.array([weights["d"]])
    else:
        cg = np.geomspace(spec["c"][0], spec["c"][1], spec["points"])
        dg = np.geomspace(spec["d"][0], spec["d"][1], spec["points"])
    return np.log(cg), np.log(dg), np.zeros(0), [(c, d, lam) for c in cg for d in dg]


def _kernel_data(bases, dry, u0, uparams, ucfg, separate):
    B, kd = wet_kernels(bases[0]["p"], bases[0]["b"], u0, uparams, ucfg, separate)
    Bdd, Bdw, kdd = dry_kernels(dry, bases[0]["p"], bases[0]["b"], u0, uparams, ucfg,
                                separate)
    return (B, kd, Bdd, Bdw, kdd)


def _same(a, b):
    return all(np.array_equal(x, y) for x, y in zip(a, b))


def fraction_top(c, d):
    """The top of a following slice's binder-fraction support [-] for its weight means c, d
    [kg]: 1, or FRACTION_SPAN times the slice's mean fraction d / c where that is below 1."""
    y_max = FRACTION_SPAN * d / c
    return 1.0 if y_max >= 1.0 - 1e-9 else float("%.12e" % y_max)


def _slice_grids(grid, pairs, spec):
    """The quadrature grid of each weight slice: the one support, or with the following
    support p_max = b_max = span c_m (c_m the weight's mass-weighted mean; b <= p bounds the
    binder; the binder fraction on [0, fraction_top], 1 or FRACTION_SPAN times the slice's
    mean fraction), the nodes uniform in the binder fraction and the basis in it
    (``laguerre_basis.fraction_basis_values``), graded Gauss nodes in p for the slice's gamma
    weight (``laguerre_basis.graded_mass_nodes``). Slices of the same c_m, shape and fraction
    top share their nodes (and kernel matrices): the nodes depend on those alone."""
    if spec is None or not spec.get("following"):
        return [grid] * len(pairs)
    out, seen = [], {}
    for c, d, lam in pairs:
        top = float(spec["span"] * (1.0 + 1.0 / lam) * c)       # span c_m
        y_max = fraction_top(c, d)
        key = (float("%.12e" % top), float("%.12e" % lam), y_max)
        if key not in seen:
            seen[key] = dict(grid, p_max=top, b_max=top, spacing=GRADED, fraction_basis=True,
                             y_max=y_max)
        out.append(seen[key])
    return out


def _slice_tensors(t, s, bases, grids, dry, k, u0, kargs, m, pd, p_ref, bd):
    """Fill the blocks of collision-velocity slice s: k the kernel data on the first basis's
    nodes; the wet and cross kernels of every other node set of the weight slices
    (``_slice_grids``) are evaluated here."""
    B, kd, Bdd, Bdw, kdd = k
    separate = kargs[-1]
    t["Qdd"][s], t["Cdd"][s] = dry_tensors(dry, Bdd, kdd, m)
    # the weight slices by node set (one set where the nodes are shared, ``_slice_grids``):
    # each set's kernel data once, the first set's from k
    groups = {}
    for w in range(len(bases)):
        groups.setdefault(id(grids[w]), []).append(w)

    def fill(key, ws):
        B_, kd_, Bdw_ = B, kd, Bdw
        if key != id(grids[0]):
            basis = bases[ws[0]]
            B_, kd_ = wet_kernels(basis["p"], basis["b"], u0, *kargs)
            Bdw_ = dry_wet_rates(dry, basis["p"], basis["b"], u0, *kargs[:2])
        for w in ws:
            t["Q"][w, s], t["Cd"][w, s], t["Cd0"][w, s] = wet_tensors(
                bases[w], B_, kd_, m, pd, separate, bd, t["capture_moments"])
            t["X"][w, s], t["XL"][w, s] = cross_tensors(dry, bases[w], Bdw_, m, p_ref)

    # the node sets are independent (kernel matrices: numba without the GIL; the tensors'
    # products: BLAS), so they run on the run's threads; a set's numbers do not depend on
    # how many
    items = list(groups.items())
    threads = min(run_threads(), len(items))

    def share(j):
        for key, ws in items[j::threads]:
            fill(key, ws)

    run_shares(share, range(threads), "laguerre-tables")


def _tables(params, config, m, weights, grid, consistent, u0_grid, p_ref, spec):
    """Every block of the aux as arrays (see ``laguerre_layout``)."""
    lnc, lnd, lnl, pairs = _weight_grid(weights, spec)
    grids = _slice_grids(grid, pairs, spec)
    bases = [wet_basis(m, (c, d, lam, weights["gam"]), g, consistent, p_ref)
             for (c, d, lam), g in zip(pairs, grids)]
    shared = grids[0] is grids[-1]
    pd = float(params[P.DROPLET_MASS])
    bd = float(droplet_liquid(params))          # the droplet's liquid [kg]
    separate = int(config[P.SEPARATE_DROPLETS]) == 1 and params[P.DROPLET_FACTOR] > 0
    dry = dry_class(m, weights["c_dry"], weights["lam_dry"], grid["p_max"], grid["n_dry"],
                    consistent, p_ref, pd, bd)
    uparams, ucfg = unit_params(params), np.asarray(config, dtype=np.int64)
    slices = [float("nan")] if u0_grid is None else list(u0_grid)

    def u0_of(x):
        return 0.0 if not np.isfinite(x) else x

    def kernels(u0):
        return _kernel_data(bases, dry, u0_of(u0), uparams, ucfg, separate)

    first = kernels(slices[0])
    last = kernels(slices[-1]) if len(slices) > 1 else first
    collapsed = len(slices) > 1 and _same(first, last)
    if collapsed:
        slices = slices[:1]
    K, nS, nW = m * m, len(slices), len(pairs)
    t = dict(Q=np.zeros((nW, nS, K * (K + 1) // 2, K)), Cd=np.zeros((nW, nS, K, K)),
             Cd0=np.zeros((nW, nS, K)), X=np.zeros((nW, nS, m, K, K)),
             XL=np.zeros((nW, nS, m, K, m)), Qdd=np.zeros((nS, m * (m + 1) // 2, m)),
             Cdd=np.zeros((nS, m, m)),
             capture_moments=int(config[P.DROPLET_LIQUID]) == 1)
    for s, u0 in enumerate(slices):
        k = first if s == 0 else (last if s == nS - 1 else kernels(u0))
        _slice_tensors(t, s, bases, grids, dry, k, u0_of(u0),
                       (uparams, ucfg, separate), m, pd, p_ref, bd)
    logu = np.log(np.array([x if np.isfinite(x) else 1.0 for x in slices]))
    t.update(logu=logu, logw=np.concatenate([lnc, lnd, lnl]), nwc=len(lnc), nwd=len(lnd),
             nwl=max(1, len(lnl)),
             f43=np.concatenate([b["f43"] for b in bases]),
             basis=np.concatenate([b["basis"] for b in bases]),
             sup=np.concatenate([b["sup"] for b in bases]), dry=dry, separate=separate,
             condw=np.array([b["cond"] for b in bases]),
             cond=max(b["cond"] for b in bases), n_nodes=len(bases[0]["u"]), slices=slices,
             collapsed=collapsed, pd=pd, following=not shared,
             wet_support=np.array([[g["p_max"], g["b_max"]] for g in grids]),
             breakage=breakage_blocks(params, config, m, bases, dry),
             drying=drying_blocks(params, config, m, bases, p_ref))
    return t


def _build(params, config, m, weights, grid, consistent, u0_grid, p_ref, spec):
    t = _tables(params, config, m, weights, grid, consistent, u0_grid, p_ref, spec)
    dry = t["dry"]
    named = [(AUX_OFF_LOGU, t["logu"]), (AUX_OFF_Q, t["Q"]), (AUX_OFF_CD, t["Cd"]),
             (AUX_OFF_CD0, t["Cd0"]), (AUX_OFF_F43, t["f43"]), (AUX_OFF_BASIS, t["basis"]),
             (AUX_OFF_SUPPORT, t["sup"]), (AUX_OFF_QDD, t["Qdd"]), (AUX_OFF_X, t["X"]),
             (AUX_OFF_XL, t["XL"]), (AUX_OFF_CDD, t["Cdd"]), (AUX_OFF_CAPMAP, dry["capmap"]),
             (AUX_OFF_F43D, dry["f43"]), (AUX_OFF_DRY_BASIS, dry["basis"]),
             (AUX_OFF_LOGW, t["logw"]), (AUX_OFF_CONDW, t["condw"]),
             (AUX_OFF_WET_SUPPORT, t["wet_support"])]
    if t["breakage"].size:                 # absent: AUX_OFF_BREAK stays 0
        named.append((AUX_OFF_BREAK, t["breakage"]))
    if t["drying"].size:                   # absent: AUX_OFF_DRYING stays 0
        named.append((AUX_OFF_DRYING, t["drying"]))
    pos = AUX_HEADER
    offs = []
    for _, blk in named:
        offs.append(pos)
        pos += blk.size
    aux = np.zeros(pos)
    for (slot, blk), o in zip(named, offs):
        aux[o:o + blk.size] = blk.ravel()
        aux[slot] = o
    K = m * m
    slices = t["slices"]
    header = {AUX_VERSION: AUX_LAYOUT_VERSION, AUX_ORDER: m, AUX_NMOM: K,
              AUX_NPAIR: K * (K + 1) // 2, AUX_NSLICE: len(slices),
              AUX_CONSISTENT: 1.0 if consistent else 0.0, AUX_MASS_SCALE: p_ref,
              AUX_P_MAX: grid["p_max"], AUX_B_MAX: grid["b_max"], AUX_N_P: grid["n_p"],
              AUX_N_B: grid["n_b"], AUX_N_NODES: t["n_nodes"], AUX_SPACING: grid["spacing"],
              AUX_DROPLET_MASS: t["pd"], AUX_SEPARATE: 1.0 if t["separate"] else 0.0,
              AUX_COND_G: t["cond"], AUX_COND_DRY: dry["cond"], AUX_N_DRY: grid["n_dry"],
              AUX_NWC: t["nwc"], AUX_NWD: t["nwd"], AUX_NWL: t["nwl"],
              AUX_FOLLOWING: 1.0 if t["following"] else 0.0,
              AUX_CAPTURE_MOMENTS: 1.0 if (t["separate"] and t["capture_moments"]) else 0.0,
              AUX_U0_FIXED: (slices[0] if (len(slices) == 1 and np.isfinite(slices[0])
                                           and not t["collapsed"]) else 0.0)}
    for slot, value in header.items():
        aux[slot] = value
    return aux
