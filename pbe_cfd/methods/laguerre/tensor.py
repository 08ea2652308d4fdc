"""Bivariate Laguerre ROM (seed 000 section III): the scene-level entry points.

What the orchestration calls: ``aux_for_scene`` (the flat ``aux`` array of tensors, built by
``laguerre_build`` and cached on disk), ``scene_initial_state``, ``population_for_output``,
``output_columns``, ``escaped_share_report`` and ``failure_hint``; ``state_names`` lists the
state entries. The numba right-hand side that reads the aux is in ``laguerre``; the basis and
its quadrature in ``laguerre_basis``; the wet class's tensors in ``laguerre_wet``, the dry
class (granules with no binder at all) and its cross terms in ``laguerre_dry``; the layouts of
state and aux in ``laguerre_layout``.

State of one cell (scaled by N_ref [1/m3] and p_ref [kg]):
``[W_ij (i, j < m, i-major), D_k (k < m), L_d, E, n_d]`` (``laguerre_layout``: L_d with
drying and separate droplets, E with drying, n_d with separate droplets): the wet granules'
mixed moments, the dry granules' moments in p, the free droplets' liquid, the evaporated
liquid, the free droplets' number.
"""
import functools
import math

import numpy as np

from ...physics import parameters as P
from ...physics.injection import droplet_liquid, droplet_moment
from ...util.population import moment_orders
from .basis import (GRADED, SPACINGS, basis_values, gamma_weight, mass_nodes,  # noqa: F401
                    fraction_basis_values, moment_index, projection_matrix,
                    quadrature, univariate_values)
from .build import (FOLLOWING_DRYING_BELOW, FOLLOWING_SHAPES, FOLLOWING_SPAN,  # noqa: F401
                    build_aux, fraction_top,
                    default_cache_dir,
                    spacing_code, theta_to_u0, unit_params)
from .layout import (AUX_B_MAX, AUX_CHECK_LEVEL, AUX_COND_DRY,  # noqa: F401
                     AUX_FOLLOWING, AUX_MASS_SCALE, AUX_NUMBER_POINTS, AUX_NWC,
                     AUX_OFF_LOGW, AUX_COND_G, NUMBER_CLOSURES, AUX_N_B, AUX_N_NODES,
                     AUX_N_P, AUX_NSLICE,
                     AUX_OFF_SUPPORT, AUX_ORDER, AUX_P_MAX, AUX_SPACING,
                     AUX_U0_FIXED, TABLE_III, dry_support_functionals, evaporated_entry,
                     free_droplets, state_names, state_size, unpack_basis, weight_corners,
                     wet_support)


def initial_state(moments, params, config, n_droplets=0.0, dry=False):
    """Scaled state from SI granule moments.

    moments: dict "M{i}{j}" -> value [kg^(i+j)/m3] or callable (i, j) -> value; missing keys
    are 0. dry: the granules carry no binder (b = 0 exactly): their moments M_k0 go into the
    dry class, binder moments must be 0. n_droplets: free droplets [1/m3], a population of
    their own if config[SEPARATE_DROPLETS] == 1, else ordinary (wet) particles of mass
    p_d = params[DROPLET_MASS] and liquid binder b_d (physics.injection.droplet_liquid). For
    a monodisperse start (N0 particles of mass p0 and binder b0) pass ``lambda i, j: N0 *
    p0**i * b0**j``: the ROM needs only the moments of the delta.
    """
    m = int(config[P.ORDER])
    K = m * m
    sep = int(config[P.SEPARATE_DROPLETS]) == 1
    nref = params[P.NUMBER_SCALE]
    pref = params[P.MASS_SCALE]
    pd = params[P.DROPLET_MASS]
    bd = droplet_liquid(params)
    out = np.zeros(state_size(m, sep, int(config[P.DRYING]) == 1))
    for i in range(m):
        for j in range(m):
            val = moments(i, j) if callable(moments) else moments.get(f"M{i}{j}", 0.0)
            if dry and j > 0 and val != 0.0:
                raise ValueError(f"dry granules carry no binder, got M{i}{j} = {val}")
            if dry and j == 0:
                out[K + i] = val / (nref * pref ** i)
            elif not dry:
                out[i * m + j] = val / (nref * pref ** (i + j))
            if not sep and n_droplets > 0.0:
                out[i * m + j] += (n_droplets * droplet_moment(pd, bd, i, j)
                                   / (nref * pref ** (i + j)))
    if sep:
        out[-1] = n_droplets / nref
        if "droplet_liquid" in state_names(m, sep, int(config[P.DRYING]) == 1):
            out[-3] = n_droplets * bd / (nref * pref)        # L_d, before E and n_d
    return out



# ---- the reconstruction as weighted particles ---------------------------------------------
@functools.lru_cache(maxsize=4096)
def _slice_quadrature(c, d, lam, gam, p_max, b_max, n_p, n_b, spacing, points, y_max):
    """``basis.quadrature`` of one weight slice (the build's nodes: with the following
    support its fraction top ``build.fraction_top``), kept per slice: an output time
    reconstructs every cell on the same few slices."""
    out = quadrature(c, d, lam, gam, p_max, b_max, n_p, n_b, spacing, points=points,
                     y_max=y_max)
    for a in out:
        a.setflags(write=False)
    return out


@functools.lru_cache(maxsize=1024)
def _slice_nodes(c, d, lam, gam, p_max, b_max, n_p, n_b, spacing, points, y_max, cp, cb,
                 fraction):
    """(phi, W, p [kg], b [kg]) of one weight slice: its quadrature (``_slice_quadrature``),
    the raw basis at its nodes (``fraction``: ``fraction_basis_values``, else
    ``basis_values``; cp, cb the bytes of the slice's Cp, Cb) and the nodes' masses. None of
    them depends on the state: an output time reconstructs every cell on the same few slices,
    each evaluated once."""
    u, v, W = _slice_quadrature(c, d, lam, gam, p_max, b_max, n_p, n_b, spacing, points, y_max)
    m = int(points)
    Cp, Cb = (np.frombuffer(x, dtype=float).reshape(m, m) for x in (cp, cb))
    phi = (fraction_basis_values if fraction else basis_values)(u, v, Cp, Cb, lam, gam)
    out = (phi, W, u * c, v * d)
    for a in out:
        a.setflags(write=False)
    return out


def wet_particles(state, aux):
    """The wet reconstruction on the quadrature nodes: (w [per N_ref], p [kg], b [kg]). With
    adaptive weights the reconstructions of the neighbouring weight slices are blended as the
    RHS blends them (each reproduces the carried moments; on shared nodes the weights are
    summed, with the following support each slice's nodes are listed with its blend weight)."""
    w_total = None
    parts = []
    following = aux[AUX_FOLLOWING] == 1.0
    for w, frac in weight_corners(state, aux):
        B = unpack_basis(aux, w)
        K = B["m"] ** 2
        p_max, b_max = wet_support(aux, w)
        phi, W, p, b = _slice_nodes(
            B["c"], B["d"], B["lam"], B["gam"], p_max, b_max, int(aux[AUX_N_P]),
            int(aux[AUX_N_B]), GRADED if following else int(aux[AUX_SPACING]), B["m"],
            fraction_top(B["c"], B["d"]) if following else 1.0, B["Cp"].tobytes(),
            B["Cb"].tobytes(), following)
        coef = B["Ginv"] @ (np.asarray(state[:K], float) * B["r"])
        part = frac * (phi @ coef) * W
        if following:                       # own nodes per slice: the corners side by side
            parts.append((part, p, b))
        elif w_total is None:
            w_total, p_total, b_total = part, p.copy(), b.copy()
        else:
            w_total = w_total + part
    if parts:
        return tuple(np.concatenate(x) for x in zip(*parts))
    return w_total, p_total, b_total


@functools.lru_cache(maxsize=64)
def _dry_nodes(c_dry, lam_dry, p_max, n_dry, m):
    """(psi, quadrature weights [du], p [kg]) of the dry class's nodes in p: the univariate
    basis at the nodes of ``mass_nodes``, which do not depend on the state (kept)."""
    u, w = mass_nodes(c_dry, lam_dry, p_max, n_dry)
    psi = univariate_values(u, projection_matrix(m, lam_dry), lam_dry)
    out = (psi, w, u * c_dry)
    for a in out:
        a.setflags(write=False)
    return out


def dry_particles(state, aux):
    """The dry reconstruction on its nodes in p: (w [per N_ref], p [kg], b = 0)."""
    B = unpack_basis(aux)
    m = B["m"]
    K = m * m
    psi, w, p = _dry_nodes(B["c_dry"], B["lam_dry"], aux[AUX_P_MAX], B["n_dry"], m)
    coef = B["Ginv_dry"] @ (np.asarray(state[K:K + m], float) * B["r_dry"])
    return (psi @ coef) * w, p.copy(), np.zeros_like(p)


def population_for_output(state, aux, arrays):
    """The reconstruction on the quadrature nodes as weighted particles (w [1/m3], p [kg],
    b [kg]) of one cell's granules, wet and dry. Weights are signed (the expansion may dip
    below zero); for the consistent variant sum w p^i b^j returns every carried moment
    (W_ij + D_i delta_j0) exactly. The dry class is left out while it is empty."""
    w, p, b = wet_particles(state, aux)
    m = int(aux[AUX_ORDER])
    if np.any(np.asarray(state[m * m:m * m + m]) != 0.0):
        wd, pdry, bd = dry_particles(state, aux)
        w, p, b = np.concatenate([w, wd]), np.concatenate([p, pdry]), np.concatenate([b, bd])
    return w * arrays.number_scale, p, b


# ---- escaped mass -------------------------------------------------------------------------
ESCAPE_WARN_SHARE = 1e-3     # warn when more than 0.1 % of the granule mass is beyond the support


def _gamma_tail(mean, var, limit, extra):
    """Upper tail Q(k + extra, limit / theta) of the gamma fit (mean, var); a (near-)delta
    counts fully if its mean is beyond the limit."""
    if not np.isfinite(mean) or mean <= 0:
        return 0.0
    if not (var > 1e-12 * mean * mean):
        return 1.0 if mean > limit else 0.0
    k = mean * mean / var
    from scipy.special import gammaincc    # here: scipy loads only for a Laguerre escape check
    return float(gammaincc(k + extra, limit / (var / mean)))


#: the name under which the escape report files mass beyond 8 c_m of a population whose c_m
#: lies inside the following grid (no [method] key widens that support)
FOLLOWING_SPAN_KEY = "following span"


def beyond_following_range(state, aux):
    """True if the wet class's mass-weighted mean mass c_m = W20 / W10 [kg] of a scaled state
    lies at or above the top of the following support's grid (``following_growth`` x the
    initial mean mass), where the weight clamps to its last slice."""
    m = int(aux[AUX_ORDER])
    s = np.asarray(state, float)
    if not (s[m] > 0.0 and s[2 * m] > 0.0):
        return False
    top = float(aux[int(aux[AUX_OFF_LOGW]) + int(aux[AUX_NWC]) - 1])
    return math.log(s[2 * m] / s[m] * aux[AUX_MASS_SCALE]) >= top


def escaped_mass_parts(state, aux, params, config):
    """Estimated shares [-] of the granule mass beyond each bound of the support, as
    ``escaped_mass_share`` fits them, keyed by the [method] key that sets the bound: the wet
    class beyond p_max ("support_mass"), beyond b_max ("support_binder"); with the following
    support, whose only bound in b is b <= p <= p_max, both under "following_growth" where the
    class's c_m has reached the top of the grid and under ``FOLLOWING_SPAN_KEY`` inside it;
    the dry class beyond its p_max ("support_mass"). Each
    share is of the granule mass of both classes, each class's share capped at 1."""
    return _escape(state, aux, params, config)[1]


def escaped_mass_share(state, aux, params, config):
    """Estimated share [-] of the granule mass carried beyond p_max or b_max.

    Wet class, m >= 3: gamma fits to the marginals -- in p from (W00, W10, W20), mass share
    beyond p_max = Q(k+1, p_max/theta); in b from the mass-weighted moments (W10, W11, W12),
    share beyond b_max = Q(k, b_max/theta) (Q the regularised upper incomplete gamma
    function). m = 2: exponential in p (mean W10/W00) and the Markov bound W11 / (b_max W10)
    in b. With the following support p_max, b_max are the smallest of the blended weight
    slices' supports. Dry class: the same fit in p to (D0, D1, D2) (exponential for m = 2),
    beyond the fixed p_max. A
    (near-)delta marginal counts fully beyond the limit if its mean is. Returns the
    mass-weighted sum over the classes, capped at 1.
    """
    return _escape(state, aux, params, config)[0]


def _escape(state, aux, params, config):
    """(escaped_mass_share, escaped_mass_parts) of one state."""
    m = int(config[P.ORDER])
    s = np.asarray(state, float)
    pref = params[P.MASS_SCALE]
    following = aux[AUX_FOLLOWING] == 1.0
    wet_p_key, wet_b_key = "support_mass", "support_binder"
    if following:
        # the grid's range is what held the population back only where the wet class's c_m
        # has reached its top slice (clamped there); inside the range the mass beyond a
        # slice's p <= 8 c_m is a population broader than the following weight's support
        wet_p_key = wet_b_key = ("following_growth" if beyond_following_range(s, aux)
                                 else FOLLOWING_SPAN_KEY)
    parts = {}

    def add(key, value):
        parts[key] = parts.get(key, 0.0) + value
    K = m * m
    # the wet class's support: the smallest among the blended slices (following support)
    pmax, bmax = (min(x) / pref for x in zip(*(wet_support(aux, w)
                                              for w, _ in weight_corners(s, aux))))
    pmax_dry = aux[AUX_P_MAX] / pref

    def p_tail(n0, n1, n2, limit=None):
        limit = pmax if limit is None else limit
        if m >= 3:
            mu = n1 / n0
            return _gamma_tail(mu, n2 / n0 - mu * mu, limit, 1.0)
        x = limit / (n1 / n0)
        return float((1.0 + x) * np.exp(-x))

    total = 0.0
    escaped = 0.0
    W = lambda i, j: s[i * m + j]  # noqa: E731
    if W(0, 0) > 0 and W(1, 0) > 0:
        if m >= 3:
            mb = W(1, 1) / W(1, 0)
            sb = _gamma_tail(mb, W(1, 2) / W(1, 0) - mb * mb, bmax, 0.0)
        else:
            sb = float(max(W(1, 1), 0.0) / (bmax * W(1, 0)))
        sp = max(0.0, p_tail(W(0, 0), W(1, 0), W(2, 0) if m >= 3 else 0.0))
        share = sp + max(0.0, sb)
        total += W(1, 0)
        escaped += W(1, 0) * min(1.0, share)
        add(wet_p_key, W(1, 0) * min(1.0, sp))
        add(wet_b_key, W(1, 0) * min(1.0, max(0.0, sb)))
    D = s[K:K + m]
    if D[0] > 0 and D[1] > 0:
        total += D[1]
        sd = D[1] * min(1.0, max(0.0, p_tail(D[0], D[1], D[2] if m >= 3 else 0.0, pmax_dry)))
        escaped += sd
        add("support_mass", sd)
    if not total > 0:
        return 0.0, {}
    return (float(min(1.0, escaped / total)),
            {k: float(min(1.0, v / total)) for k, v in parts.items()})


def escaped_share_report(states, aux, arrays):
    """(largest escaped granule-mass share over the rows [-], warning text or "").

    states: scaled states, one row per output time (or cell)."""
    states = np.atleast_2d(states)
    shares = np.array([escaped_mass_share(s, aux, arrays.params, arrays.config)
                       for s in states])
    k = int(np.argmax(shares)) if shares.size else 0
    share = float(shares[k]) if shares.size else 0.0
    text = ""
    if share > ESCAPE_WARN_SHARE:
        parts = escaped_mass_parts(states[k], aux, arrays.params, arrays.config)
        text = (f"Laguerre ROM: {share:.2%} of the granule mass lies beyond the integration "
                f"support ({support_text(states[k], aux)}) at output row {k}; the tensor does "
                f"not see it -- {support_advice(aux, parts)}")
    return share, text


def support_text(state, aux):
    """The supports a state's tensors integrate over, with the [method] keys that set them."""
    dry = f"p_max = {aux[AUX_P_MAX]:.3g} kg ([method] support_mass)"
    if aux[AUX_FOLLOWING] != 1.0:
        return f"{dry}, b_max = {aux[AUX_B_MAX]:.3g} kg (support_binder)"
    p_top = max(wet_support(aux, w)[0] for w, _ in weight_corners(state, aux))
    return (f"wet class: following support p_max = {p_top:.3g} kg, up to the range of "
            f"[method] following_growth; dry class: {dry}")


def support_advice(aux, parts=None):
    """What to change in the scene when mass leaves the support: with ``parts``
    (``escaped_mass_parts``) each [method] key whose bound holds back more than
    ESCAPE_WARN_SHARE of the granule mass, named with its value and share; the generic
    advice otherwise."""
    values = {"support_mass": f"{aux[AUX_P_MAX]:.3g} kg", "support_binder":
              f"{aux[AUX_B_MAX]:.3g} kg", "following_growth": "the following range"}
    named = [k for k, v in sorted((parts or {}).items(), key=lambda kv: -kv[1])
             if v > ESCAPE_WARN_SHARE]
    if FOLLOWING_SPAN_KEY in named:
        broad = (f"{parts[FOLLOWING_SPAN_KEY]:.1%} of the granule mass lies beyond p <= "
                 f"{FOLLOWING_SPAN:g} c_m of the wet class (its c_m inside the range of "
                 "[method] following_growth, which is not what held it back): the population "
                 "is broader than the following weight's support")
        others = [k for k in named if k != FOLLOWING_SPAN_KEY]
        rest = f"; also {support_advice(aux, {k: parts[k] for k in others})}" if others else ""
        return f"{broad}; use qmom{rest}"
    if named:
        too_small = "; ".join(f"[method] {k} ({values[k]}) is too small: {parts[k]:.1%} of the "
                              "granule mass lies beyond it" for k in named)
        way = ("raise it" if len(named) == 1 else "raise them")
        if aux[AUX_FOLLOWING] != 1.0:
            way += ", or set [method] following_support = true"
        return f"{too_small}; {way}, or use qmom"
    if aux[AUX_FOLLOWING] == 1.0:
        return "raise [method] following_growth (wet) or support_mass (dry), or use qmom"
    return ("set [method] following_support = true, or widen support_mass / support_binder, "
            "or use qmom")


# ---- scene-level helpers (called by the orchestration) -------------------------------------
# quadrature spacing for scenes that do not name one ([method] grid_spacing): "fraction" -- on
# the seed scenario it brings the consistent ROM from 10-13 % to within 3-9 % of the cNMC at
# table III's 20 x 20 points; "uniform" reproduces table III's increments literally.
SCENE_SPACING = "fraction"


def scene_weights_support(scene):
    """(weights, support) dicts of build_aux from the scene's [method] table (SI). The dry
    class's weight has the mean ``dry_weight_mean_mass`` (default: the initial granules' mean
    mass, where dry granules sit) and shape ``dry_weight_shape_mass``."""
    m = scene.method.options
    weights = dict(c=m.weight_mean_mass, d=m.weight_mean_binder, lam=m.weight_shape_mass,
                   gam=m.weight_shape_binder,
                   c_dry=getattr(m, "dry_weight_mean_mass", None) or scene.initial.mean_mass,
                   lam_dry=m.dry_weight_shape_mass)
    support = dict(p_max=m.mass_support, b_max=m.binder_support, n_p=m.grid_mass,
                   n_b=m.grid_binder, spacing=getattr(m, "grid_spacing", SCENE_SPACING),
                   n_dry=getattr(m, "dry_grid_mass", None) or m.grid_mass)
    return weights, support


def aux_for_scene(scene, arrays, theta_grid=None, cache_dir=None):
    """aux of the Laguerre ROM for a scene and its packed arrays (``model.pack``).

    The collision velocity is fixed (one tensor slice) when the scene's domain gives
    ``collision_velocity`` or when no theta_grid [m2/s2] is passed (well-mixed: the cell's u0,
    4 sqrt(Theta / pi) from its granular temperature); otherwise the tensor is tabulated on
    theta_grid (u0 = 4 sqrt(Theta / pi)). With ``adaptive_weights`` (the default) the wet
    weight means follow the wet class on an ``adaptive_points`` x ``adaptive_points`` grid
    (``laguerre_build``); weight_mean_mass and weight_mean_binder then do not enter.
    """
    weights, support = scene_weights_support(scene)
    u0 = getattr(scene.domain, "collision_velocity", None)
    if u0 is not None:
        theta_grid = None
    elif theta_grid is None:
        u0 = float(theta_to_u0(max(getattr(scene.domain, "granular_temperature", None) or 0.0,
                                   0.0)))
    if not (u0 is None or u0 > 0):
        u0 = None
    points = int(getattr(scene.method.options, "adaptive_points", 0) or 0)
    adaptive = dict(points=points) if getattr(scene.method.options, "adaptive_weights", False) else None
    if scene.method.options.follows:
        adaptive = following_spec(scene, arrays)
        support["p_max"] = max(support["p_max"], FOLLOWING_SPAN * weights["c_dry"])
    aux = build_aux(arrays.params, arrays.config, scene.method.options.order, weights=weights,
                    support=support, consistent=scene.method.options.consistent,
                    theta_grid=theta_grid, cache_dir=cache_dir, collision_velocity=u0,
                    adaptive=adaptive)
    options = scene.method.options
    aux[AUX_NUMBER_POINTS] = NUMBER_CLOSURES[number_closure(
        options.follows, options.number_closure, options.order)]
    return aux


def number_closure(following, given=None, order=3):
    """The closure of the rows of aggregation and droplet capture ("tensor", "points": the
    rows of order <= 2 on the point measures, "points-all": every wet row on them):
    ``given``, or by default "points-all" with the following support (measured on the batch
    proxies, the bed batch, the held-out suite and the hard cell next to packing,
    docs/results/laguerre.md: the tensors' number row turns positive for a broad class,
    their capture pushes a class born at one mass outside, their rows of order 3 and 4 turn
    negative next to packing; at m = 4 "points" stops at its step floor on both seed
    scenarios, at 217 and 227 s, where "points-all" finishes), and "tensor" with the fixed
    seed support (where the tensors are exact or within 1.5%)."""
    if given:
        return given
    return "points-all" if following else "tensor"


def following_spec(scene, arrays):
    """The following support's grid for a scene: wet weight means c from a quarter of the
    smaller of the initial mean mass and the droplet mass up to ``following_growth`` times
    the initial mean mass [kg], and with ``following_shape`` (the default) the gamma shapes
    of ``build.FOLLOWING_SHAPES`` (docs/physics.md section 9.2; without it the fixed
    ``weight_shape_mass``); with [drying] the binder fractions ``build.FOLLOWING_DRYING_BELOW``
    below ``build.FOLLOWING_RATIO``'s."""
    c0 = float(scene.initial.mean_mass)
    pd = float(arrays.params[P.DROPLET_MASS])
    low = 0.25 * (min(c0, pd) if pd > 0 else c0)
    shapes = (FOLLOWING_SHAPES if getattr(scene.method.options, "following_shape", True)
              else None)
    spec = dict(following=True, c=(low, c0 * float(scene.method.options.following_growth)),
                shapes=shapes)
    if getattr(scene, "drying", None) is not None:
        spec["y_below"] = FOLLOWING_DRYING_BELOW
    return spec


def table_bytes(method) -> int:
    """Peak memory [bytes] of building the ROM's tables for a scene's ``method.options``
    (``laguerre_build``): on N = grid_mass x grid_binder wet nodes and n = dry_grid_mass dry
    nodes, the pair-rate matrices of two collision-velocity slices held at once (2 (N^2 + n N
    + n^2) doubles), the aggregation tensor's two N x K^2 products (K = order^2) and one
    N x (K + 8) basis per wet weight (adaptive_points^2 of them with adaptive weights)."""
    n_wet = int(method.grid_mass) * int(method.grid_binder)
    n_dry = int(method.dry_grid_mass)
    k = int(method.order) ** 2
    weights = int(method.adaptive_points) ** 2 if method.adaptive_weights else 1
    doubles = (2 * (n_wet * n_wet + n_dry * n_wet + n_dry * n_dry) + 2 * n_wet * k * k
               + weights * n_wet * (k + 8))
    return 8 * doubles


def scene_initial_state(scene, arrays, granule_moment):
    """Scaled initial state of a scene: granule_moment(i, j) [kg^(i+j)/m3] of the initial
    granules (free droplets excluded); granules without binder (initial.binder_fraction = 0)
    start in the dry class unless the scene's [method] sets dry_class = false (then they are
    a bivariate population at b = 0, the formulation before the dry class)."""
    dry = bool(getattr(scene.method.options, "dry_class", True)) and scene.initial.binder_fraction == 0.0
    return initial_state(granule_moment, arrays.params, arrays.config,
                         n_droplets=scene.initial.droplet_number_density, dry=dry)


def scene_keys(t, defaults):
    """The dry-class, adaptive-weight and following-support keys of a scene's ``[method]``
    table (read with the
    scene's table reader ``t``; ``defaults``: the ``LaguerreOptions`` class)."""
    kw = {"dry_class": t.boolean("dry_class", defaults.dry_class)}
    if t.has("dry_weight_mean_mass"):
        kw["dry_weight_mean_mass"] = t.number("dry_weight_mean_mass", positive=True, unit="kg")
    kw["dry_weight_shape_mass"] = t.number("dry_weight_shape_mass",
                                           defaults.dry_weight_shape_mass, positive=True)
    kw["dry_grid_mass"] = t.number("dry_grid_mass", defaults.dry_grid_mass, integer=True,
                                   low=4, high=4000)
    kw["adaptive_weights"] = t.boolean("adaptive_weights", defaults.adaptive_weights)
    kw["adaptive_points"] = t.number("adaptive_points", defaults.adaptive_points, integer=True,
                                     low=2, high=33)
    # unset: the following support for order >= 3 unless support_mass or support_binder is set
    if t.has("following_support"):
        kw["following_support"] = t.boolean("following_support", False)
    kw["following_growth"] = t.number("following_growth", defaults.following_growth,
                                      low=2.0, high=1e9)
    kw["following_shape"] = t.boolean("following_shape", defaults.following_shape)
    # the rows on the point measures; not given: ``number_closure`` decides with the support
    if t.has("number_closure"):
        kw["number_closure"] = t.choice("number_closure", tuple(NUMBER_CLOSURES))
    return kw


def plan_columns(plan, arrays, states, aux, populations=None):
    """SI output columns of a run's scaled states (``output_columns``; plan: the run's
    ``methods.entry.MethodPlan``, its bivariate flag and density [kg/m3]); with drying also the
    liquid inventory [kg/m3] (evaporated: its state entry; held by free droplets, n_d b_d or
    their carried L_d; held by granules) and the moisture content M01 / (M10 - M01) [-], as the other
    methods' (docs/physics.md section 15)."""
    out = output_columns(states, aux, arrays, plan.bivariate, plan.density,
                         populations)
    if int(arrays.config[P.DRYING]) == 1:
        states = np.atleast_2d(states)
        nd, _, liquid = free_droplets(states, arrays.params, arrays.config)
        droplets = nd * liquid
        evaporated = states[:, evaporated_entry(arrays.config)]
        out["liquid_evaporated"] = evaporated * arrays.number_scale * arrays.mass_scale
        out["liquid_droplets"] = droplets
        out["liquid_granules"] = out["M01"] - droplets
        dry = out["M10"] - out["M01"]
        out["moisture_content"] = np.where(dry > 0, out["M01"] / np.where(dry > 0, dry, 1.0),
                                           0.0)
    return out


def output_columns(states, aux, arrays, bivariate, density, populations=None):
    """SI output columns of scaled states (one row per time or cell): "M{i}{j}" [kg^(i+j)/m3]
    of the whole population (wet + dry granules + free droplets; the standard set first, M20
    and M02 for m = 2 from the reconstruction), "droplet_number_density" [1/m3] if droplets
    are separate, "dry_M{k}0" [kg^k/m3] (the dry granules' moments, k < m; dry_M00 their number
    density) and "dry_mass_fraction" [-] (their share of the solids mass M10), "d32_m", "d43_m" [m] of granules and droplets, "binder_fraction"
    [-] = M01 / M10. Each row's weighted particles (w [1/m3], p, b [kg]) are appended to
    ``populations`` if a list is passed."""
    from ...util.population import DERIVED, columns_from_particles, mean_diameters, moment_columns
    states = np.atleast_2d(states)
    m = int(aux[AUX_ORDER])
    K = m * m
    separate = int(arrays.config[P.SEPARATE_DROPLETS]) == 1 and states.shape[1] > K + m
    carried = [f"M{i}{j}" for i in range(m) for j in range(m)]
    cols = moment_columns(carried, bivariate)
    extra = ((["droplet_number_density"] if separate else [])
             + [f"dry_M{k}0" for k in range(m)] + ["dry_mass_fraction"])
    out = {c: np.zeros(len(states)) for c in cols + extra + list(DERIVED)}
    n_ref, p_ref = arrays.number_scale, arrays.mass_scale
    droplets = free_droplets(states, arrays.params, arrays.config)   # [1/m3], [kg], [kg]
    for r, state in enumerate(states):
        w, p, b = population_for_output(state, aux, arrays)
        if populations is not None:
            populations.append((w, p, b))
        nd, pd, bd = (float(x[r]) for x in droplets)
        estimated = columns_from_particles(w, p, b, [c for c in cols if c not in carried])
        for c in cols:
            i, j = moment_orders(c)
            if c in carried:
                value = state[i * m + j] + (state[K + i] if j == 0 else 0.0)
                value *= n_ref * p_ref ** (i + j)
            else:
                value = estimated[c]
            out[c][r] = value + nd * droplet_moment(pd, bd, i, j)
        if separate:
            out["droplet_number_density"][r] = nd
        for k in range(m):
            out[f"dry_M{k}0"][r] = state[K + k] * n_ref * p_ref ** k
        m10 = out["M10"][r]
        out["dry_mass_fraction"][r] = state[K + 1] * n_ref * p_ref / m10 if m10 > 0 else 0.0
        ww = np.append(w, nd) if nd > 0 else w
        pp = np.append(p, pd) if nd > 0 else p
        out["d32_m"][r], out["d43_m"][r] = mean_diameters(ww, pp, density)
        out["binder_fraction"][r] = out["M01"][r] / m10 if bivariate and m10 > 0 else 0.0
    return out


def failure_hint(state, aux, arrays):
    """Context for a cell the integrator stopped: the share of the granule mass that had left
    the integration support (the usual reason the ROM's moments stop being realizable)."""
    share, _ = escaped_share_report(np.atleast_2d(state), aux, arrays)
    where = f"({support_text(np.ravel(state), aux)})"
    if share <= ESCAPE_WARN_SHARE:
        return (f"; the population was inside the Laguerre support {where}, {share:.1%} of "
                "the granule mass beyond it: the support is not the cause, the stop is the "
                "integrator's (above)")
    parts = escaped_mass_parts(np.ravel(state), aux, arrays.params, arrays.config)
    return (f"; {share:.1%} of the granule mass had left the Laguerre support {where}: "
            f"{support_advice(aux, parts)}")
