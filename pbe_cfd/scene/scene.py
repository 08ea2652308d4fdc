"""Scene files: TOML -> validated, frozen dataclasses (the keys: docs/scene-keys.md).

A table present means that effect runs; an absent table is not computed at all. Every error
names the file, the key and what was expected, and is raised as ``SceneError``."""
from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from . import coupling as scene_coupling, limits, spray
from .drying import Drying, drying_refusals, parse_drying
from .method import COMMON_METHOD_KEYS, Method
from .output import Output, parse_output
from .spray import BinderInjection, Zone  # noqa: F401 (part of the scene API)
from ..io.openfoam import case_keys
from ..methods import registry
from ..physics.breakage import DAUGHTERS_BY_NAME, SELECTION_BY_NAME
from ..physics.efficiency import EFFICIENCY_BY_NAME
from ..physics.kernels import KERNEL_BY_NAME

#: the names the scene accepts, from the registries (physics.kernels, physics.efficiency,
#: methods.registry)
KERNEL_NAMES, EFFICIENCY_NAMES = tuple(KERNEL_BY_NAME), tuple(EFFICIENCY_BY_NAME)
SELECTION_NAMES, DAUGHTER_NAMES = tuple(SELECTION_BY_NAME), tuple(DAUGHTERS_BY_NAME)


class SceneError(ValueError):
    """A scene file that cannot be used: names the file, the key and what was expected."""

    def __init__(self, path, key, expected):
        self.path = str(path)
        self.key = key
        self.expected = expected
        where = f"{self.path}: " + (f"[{key}] " if key else "")
        super().__init__(where + expected)


# ------------------------------------------------------------------------------ dataclasses
@dataclass(frozen=True)
class Domain:
    """Where the population lives. Well-mixed: one cell (granular_temperature [m2/s2],
    solids_fraction [-], collision_velocity [m/s]). OpenFOAM: the case directory (absolute;
    relative to the scene file in TOML) or bundled snapshot, the written time, alpha_min [-],
    the solids phase name, whether a material mismatch with the case is accepted."""
    type: str
    granular_temperature: float | None = None
    solids_fraction: float | None = None
    collision_velocity: float | None = None
    alpha_max: float = 0.62
    alpha_min_friction: float | None = None
    case: str | None = None
    time: str = "latest"
    alpha_min: float = 0.05
    phase: str = "particles"
    accept_material_mismatch: bool = False


@dataclass(frozen=True)
class Material:
    """Particle and binder properties (SI) and efficiency constants (dimensionless unless
    stated): density [kg/m3], binder_density [kg/m3], binder_viscosity [Pa s], asperity [m],
    gyration_radius [m]."""
    density: float
    binder_density: float | None = None
    binder_viscosity: float | None = None
    accessible_binder_slope: float | None = None
    accessible_binder_centre: float | None = None
    binder_layer_slope: float | None = None
    binder_layer_centre: float | None = None
    asperity: float | None = None
    gyration_radius: float | None = None
    stokes_switch_width: float = 0.0
    porosity: float | None = None
    saturation_max: float | None = None


@dataclass(frozen=True)
class Initial:
    """Initial population: number_density [1/m3] of granules of mean_mass [kg] (or diameter
    [m]), binder_fraction [-], plus droplet_number_density [1/m3] free droplets."""
    distribution: str
    number_density: float
    mean_mass: float
    binder_fraction: float = 0.0
    droplet_number_density: float = 0.0


@dataclass(frozen=True)
class Aggregation:
    """Aggregation: kernel name, rate k0 (units per kernel), efficiency factor names,
    droplet_factor [-] (None: droplets are ordinary particles), reference_diameter [m]."""
    kernel: str
    rate: float
    efficiency: tuple = ()
    droplet_factor: float | None = None
    reference_diameter: float | None = None

    @property
    def reads_binder(self) -> bool:
        """True if an efficiency factor of it depends on the granules' binder."""
        return any(EFFICIENCY_BY_NAME[f].uses_binder for f in self.efficiency)


@dataclass(frozen=True)
class Breakage:
    """Breakage (physics.breakage): selection and daughters names, rate s0 [1/s], exponent a
    [-], reference_mass p_ref [kg] (None: the initial mean granule mass),
    reference_granular_temperature Theta_ref [m2/s2], yield_strength Y [Pa] and
    critical_deformation_number St_def* [-] of the optional Stokes deformation gate."""
    selection: str
    rate: float
    daughters: str = "uniform"
    exponent: float = 1.0
    reference_mass: float | None = None
    reference_granular_temperature: float | None = None
    yield_strength: float | None = None
    critical_deformation_number: float | None = None


@dataclass(frozen=True)
class Transport:
    """Transport of the population by the granular flux (OpenFOAM domains): courant [-] (CFL
    limit of the upwind substeps, <= 1), split_step [s] (operator-splitting step; None: the
    default of ``pbe_cfd.transport.operator``), splitting ("strang" or "lie")."""
    courant: float = 0.5
    split_step: float | None = None
    splitting: str = "strang"


@dataclass(frozen=True)
class Scene:
    """A validated scene. The effects (``EFFECTS``: aggregation, binder_injection, breakage,
    drying, transport, coupling) are None when their table is absent: that effect is not
    computed at all."""
    name: str
    end_time: float
    output_interval: float
    domain: Domain
    material: Material
    initial: Initial
    method: Method
    aggregation: Aggregation | None = None
    binder_injection: BinderInjection | None = None
    transport: Transport | None = None
    breakage: Breakage | None = None
    drying: Drying | None = None
    coupling: scene_coupling.Coupling | None = None   # two-way coupling; None: one-way
    output: Output | None = None    # outputs on request (the per-cell size distribution)
    source: str = ""
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def bivariate(self) -> bool:
        """True if binder mass is a coordinate: binder at the start or binder injected."""
        return self.initial.binder_fraction > 0.0 or self.binder_injection is not None

    @property
    def separate_droplets(self) -> bool:
        """True if droplets are a population of their own (droplet_factor set)."""
        return (self.aggregation is not None and self.aggregation.droplet_factor is not None
                and self.bivariate)

    def with_method(self, **changes) -> "Scene":
        """A copy with ``[method]`` keys replaced, common or the method's own
        (``Method.replaced``; used by studies and tests)."""
        return dataclasses.replace(self, method=self.method.replaced(**changes))


# ------------------------------------------------------------------------------ validation
#: the optional tables that each switch an effect on (absent: not computed), as Scene fields
EFFECTS = ("aggregation", "binder_injection", "breakage", "drying", "transport", "coupling")

_TABLES = ("scene", "domain", "material", "initial", "aggregation", "binder_injection",
           "method", "transport", "breakage", "coupling", "drying", "output")


class _Table:
    """Reads keys of one TOML table, remembering which were used to report unknown keys."""

    def __init__(self, path, name, data):
        self.path = path
        self.name = name
        if not isinstance(data, dict):
            raise SceneError(path, name, "expected a table")
        self.data = data
        self.used = set()

    def _key(self, key):
        return f"{self.name}.{key}" if self.name else key

    def has(self, key):
        return key in self.data

    def fail(self, key, expected):
        """Refuse the key's value: a SceneError naming the file, the key and ``expected``."""
        raise SceneError(self.path, self._key(key), expected)

    def raw(self, key, default=None):
        self.used.add(key)
        return self.data.get(key, default)

    def number(self, key, default=..., *, positive=False, non_negative=False, low=None,
               high=None, unit="", integer=False):
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                raise SceneError(self.path, self._key(key),
                                 f"missing required key: expected a number{_u(unit)}")
            return default
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(self.path, self._key(key),
                             f"expected a number{_u(unit)}, got {value!r}")
        if integer and (not isinstance(value, int)):
            raise SceneError(self.path, self._key(key), f"expected an integer, got {value!r}")
        if not math.isfinite(value):
            raise SceneError(self.path, self._key(key), f"expected a finite number, got {value}")
        if positive and not value > 0:
            raise SceneError(self.path, self._key(key),
                             f"expected a positive number{_u(unit)}, got {value}")
        if non_negative and value < 0:
            raise SceneError(self.path, self._key(key),
                             f"expected a non-negative number{_u(unit)}, got {value}")
        if low is not None and value < low:
            raise SceneError(self.path, self._key(key), f"expected >= {low}, got {value}")
        if high is not None and value > high:
            raise SceneError(self.path, self._key(key), f"expected <= {high}, got {value}")
        return int(value) if integer else float(value)

    def choice(self, key, choices, default=...):
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                raise SceneError(self.path, self._key(key),
                                 f"missing required key: expected one of {', '.join(choices)}")
            return default
        value = self.data[key]
        if value not in choices:
            raise SceneError(self.path, self._key(key),
                             f"expected one of {', '.join(choices)}, got {value!r}")
        return value

    def string(self, key, default=...):
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                raise SceneError(self.path, self._key(key), "missing required key: expected a string")
            return default
        value = self.data[key]
        if not isinstance(value, str):
            raise SceneError(self.path, self._key(key), f"expected a string, got {value!r}")
        return value

    def boolean(self, key, default):
        self.used.add(key)
        value = self.data.get(key, default)
        if not isinstance(value, bool):
            raise SceneError(self.path, self._key(key), f"expected true or false, got {value!r}")
        return value

    def finish(self, allowed_extra=()):
        unknown = sorted(set(self.data) - self.used - set(allowed_extra))
        if unknown:
            raise SceneError(self.path, self._key(unknown[0]),
                             f"unknown key; expected one of: {', '.join(sorted(self.used))}")


def _u(unit):
    return f" in {unit}" if unit else ""


def _vector3(path, key, value):
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise SceneError(path, key, f"expected a list of three numbers (x, y, z in m), got {value!r}")
    return tuple(float(v) for v in value)


def load_scene(source) -> Scene:
    """Read and validate a scene from a TOML file path, or a bundled scene name."""
    path = resolve_scene_path(source)
    try:
        text = path.read_text()
    except OSError as exc:
        raise SceneError(path, None, f"cannot read the file: {exc.strerror}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(path, None, f"not a valid TOML file: {exc}") from None
    return scene_from_dict(data, path)


def scene_from_dict(data: dict, path="<scene>") -> Scene:
    """Validate a parsed TOML document into a ``Scene`` (the keys: docs/scene-keys.md)."""
    for key in data:
        if key not in _TABLES:
            raise SceneError(path, key, f"unknown table; expected one of: {', '.join(_TABLES)}")
    for key in ("scene", "domain", "material", "initial", "method"):
        if key not in data:
            raise SceneError(path, key, "missing required table")

    t = _Table(path, "scene", data["scene"])
    name = t.string("name", Path(str(path)).stem)
    end_time = t.number("end_time", positive=True, unit="s")
    output_interval = t.number("output_interval", positive=True, unit="s")
    if output_interval > end_time:
        raise SceneError(path, "scene.output_interval",
                         f"expected at most end_time ({end_time} s), got {output_interval}")
    t.finish()

    domain = _domain(path, data["domain"])
    aggregation = _aggregation(path, data["aggregation"]) if "aggregation" in data else None
    injection = (spray.parse_injection(path, data["binder_injection"], domain, _Table,
                                       _vector3, SceneError)
                 if "binder_injection" in data else None)
    material = _material(path, data["material"], aggregation, injection)
    initial = _initial(path, data["initial"], material, domain)
    method = _method(path, data["method"])
    transport = None
    if "transport" in data:
        tt = _Table(path, "transport", data["transport"])
        transport = Transport(courant=tt.number("courant", 0.5, positive=True, high=1.0),
                              split_step=tt.number("split_step", None, positive=True, unit="s"),
                              splitting=tt.choice("splitting", ("strang", "lie"), "strang"))
        tt.finish()
        if domain.type != "openfoam":
            raise SceneError(path, "transport",
                             "transport needs a domain with cells: expected domain.type = \"openfoam\"")

    breakage = _breakage(path, data["breakage"], domain) if "breakage" in data else None
    drying = (parse_drying(path, data["drying"], _Table, SceneError) if "drying" in data
              else None)
    coupling = (scene_coupling.parse_coupling(_Table(path, "coupling", data["coupling"]),
                                              domain, SceneError) if "coupling" in data else None)
    output = (parse_output(path, data["output"], domain, _Table, _vector3, SceneError)
              if "output" in data else None)
    scene = Scene(name=name, end_time=end_time, output_interval=output_interval, domain=domain,
                  material=material, initial=initial, method=method, aggregation=aggregation,
                  binder_injection=injection, transport=transport, breakage=breakage,
                  drying=drying, coupling=coupling, output=output, source=str(path), raw=data)
    _cross_checks(path, scene)
    for key, refusal in limits.scene_refusals(scene, registry.METHODS[scene.method.name]):
        raise SceneError(path, key, refusal)
    return scene


def _domain(path, data):
    t = _Table(path, "domain", data)
    kind = t.choice("type", ("well-mixed", "openfoam"))
    alpha_max = t.number("alpha_max", 0.62, positive=True, high=1.0)
    alpha_min_friction = t.number("alpha_min_friction", None, positive=True, high=alpha_max)
    if kind == "well-mixed":
        alpha = t.number("solids_fraction", None, non_negative=True)
        if alpha is not None and alpha >= alpha_max:
            raise SceneError(path, "domain.solids_fraction",
                             f"expected a solids fraction below alpha_max = {alpha_max}, got {alpha}")
        d = Domain(type=kind, alpha_max=alpha_max, alpha_min_friction=alpha_min_friction,
                   granular_temperature=t.number("granular_temperature", None, non_negative=True,
                                                 unit="m2/s2"),
                   solids_fraction=alpha,
                   collision_velocity=t.number("collision_velocity", None, non_negative=True,
                                               unit="m/s"))
    else:
        time = case_keys.case_time(path, t.raw("time", "latest"), SceneError)
        d = Domain(type=kind, alpha_max=alpha_max, alpha_min_friction=alpha_min_friction,
                   case=case_keys.case_path(path, t.string("case", "bundled:fluid_bed_small")),
                   time=time, alpha_min=t.number("alpha_min", 0.05, non_negative=True, high=1.0),
                   phase=case_keys.phase(path, t.string("phase", "particles"), SceneError),
                   accept_material_mismatch=t.boolean("accept_material_mismatch", False))
    t.finish()
    return d


def _aggregation(path, data):
    t = _Table(path, "aggregation", data)
    kernel = t.choice("kernel", KERNEL_NAMES)
    rate = t.number("rate", positive=True, unit="the kernel's units")
    eff = t.raw("efficiency", [])
    if not isinstance(eff, list) or any(e not in EFFICIENCY_NAMES for e in eff):
        raise SceneError(path, "aggregation.efficiency",
                         f"expected a list of factors among {', '.join(EFFICIENCY_NAMES)}, got {eff!r}")
    if len(set(eff)) != len(eff):
        raise SceneError(path, "aggregation.efficiency", f"factor listed twice: {eff!r}")
    agg = Aggregation(kernel=kernel, rate=rate, efficiency=tuple(eff),
                      droplet_factor=t.number("droplet_factor", None, non_negative=True),
                      reference_diameter=t.number("reference_diameter", None, positive=True,
                                                  unit="m"))
    t.finish()
    return agg


#: [breakage] keys a selection may read: (default (... = required), number options)
_BREAKAGE_KEYS = {
    "exponent": (1.0, dict(non_negative=True)),
    "reference_mass": (None, dict(positive=True, unit="kg")),
    "reference_granular_temperature": (..., dict(positive=True, unit="m2/s2")),
    "yield_strength": (None, dict(positive=True, unit="Pa")),
    "critical_deformation_number": (None, dict(positive=True)),
}


def _breakage(path, data, domain):
    """The [breakage] table: only the keys its selection function reads (physics.breakage)."""
    t = _Table(path, "breakage", data)
    entry = SELECTION_BY_NAME[t.choice("selection", SELECTION_NAMES)]
    kw = dict(selection=entry.name, rate=t.number("rate", non_negative=True, unit="1/s"),
              daughters=t.choice("daughters", DAUGHTER_NAMES, "uniform"))
    for key in entry.keys:
        default, options = _BREAKAGE_KEYS[key]
        kw[key] = t.number(key, default, **options)
    if (kw.get("yield_strength") is None) != (kw.get("critical_deformation_number") is None):
        raise SceneError(path, "breakage.critical_deformation_number",
                         "the Stokes deformation gate needs both yield_strength (Pa) and "
                         "critical_deformation_number (or neither: no gate)")
    if (entry.cell_fields and domain.type == "well-mixed"
            and (domain.granular_temperature is None or domain.solids_fraction is None)):
        raise SceneError(path, "domain.granular_temperature",
                         f"the {entry.name} breakage selection needs granular_temperature "
                         "(m2/s2) and solids_fraction of the well-mixed domain")
    t.finish()
    return Breakage(**kw)


def _material(path, data, aggregation, injection):
    t = _Table(path, "material", data)
    values = dict(
        density=t.number("density", positive=True, unit="kg/m3"),
        binder_density=t.number("binder_density", None, positive=True, unit="kg/m3"),
        binder_viscosity=t.number("binder_viscosity", None, positive=True, unit="Pa s"),
        accessible_binder_slope=t.number("accessible_binder_slope", None),
        accessible_binder_centre=t.number("accessible_binder_centre", None),
        binder_layer_slope=t.number("binder_layer_slope", None),
        binder_layer_centre=t.number("binder_layer_centre", None),
        asperity=t.number("asperity", None, positive=True, unit="m"),
        gyration_radius=t.number("gyration_radius", None, positive=True, unit="m"),
        stokes_switch_width=t.number("stokes_switch_width", 0.0, non_negative=True),
        porosity=t.number("porosity", None, positive=True, high=0.999),
        saturation_max=t.number("saturation_max", None, positive=True),
    )
    t.finish()
    factors = aggregation.efficiency if aggregation else ()
    for factor in factors:
        for key in EFFICIENCY_BY_NAME[factor].material:
            if values[key] is None:
                raise SceneError(path, f"material.{key}",
                                 f"missing: the {factor} efficiency needs it")
    if injection is not None and values["binder_density"] is None:
        raise SceneError(path, "material.binder_density",
                         "missing: binder injection needs the binder density (kg/m3)")
    return Material(**values)


def _initial(path, data, material, domain):
    t = _Table(path, "initial", data)
    dist = t.choice("distribution", ("monodisperse", "exponential"))
    if domain.type == "openfoam":
        if t.has("number_density"):
            raise SceneError(path, "initial.number_density",
                             "not used in an openfoam domain: granules fill each cell's solids "
                             "fraction, n = alpha rho_s / p0; remove the key")
        n0 = 0.0
    else:
        n0 = t.number("number_density", non_negative=True, unit="1/m3")
    has_mass = t.has("mean_mass")
    has_d = t.has("diameter")
    if has_mass == has_d:
        raise SceneError(path, "initial.mean_mass",
                         "expected exactly one of mean_mass (kg) or diameter (m)")
    if has_mass:
        mass = t.number("mean_mass", positive=True, unit="kg")
    else:
        d = t.number("diameter", positive=True, unit="m")
        mass = material.density * math.pi / 6.0 * d ** 3
    init = Initial(distribution=dist, number_density=n0, mean_mass=mass,
                   binder_fraction=t.number("binder_fraction", 0.0, non_negative=True, high=1.0),
                   droplet_number_density=t.number("droplet_number_density", 0.0, unit="1/m3",
                                                   non_negative=True))
    t.finish()
    return init


def _method(path, data):
    """The [method] table: the common keys, then the method's own (its entry's ``scene_keys``
    into its options dataclass). A key of another method, or of none, is refused naming the
    method and the keys it takes."""
    t = _Table(path, "method", data)
    name = t.choice("name", registry.METHOD_NAMES)
    entry = registry.METHODS[name]
    kw = dict(name=name)
    kw["rtol"] = t.number("rtol", 1.0e-8, positive=True, high=0.1)
    kw["atol"] = t.number("atol", 1.0e-14, positive=True)
    # per-cell time integrator of the moment methods (pbe_cfd.integrate); cnmc ignores it
    kw["integrator"] = t.choice("integrator", ("explicit", "implicit", "auto"), "auto")
    # the size-distribution reconstruction (docs/physics.md 11.1); None: the method's first
    if t.has("size_distribution") and not entry.distributions:
        raise SceneError(path, "method.size_distribution",
                         f"the {name} method has no reconstruction to choose; remove the key")
    kw["size_distribution"] = t.choice("size_distribution", entry.distributions, None)
    options = entry.options_class(**entry.scene_keys(t, entry.options_class))
    unknown = sorted(set(t.data) - t.used)
    if unknown:
        key = unknown[0]
        takes = ", ".join(COMMON_METHOD_KEYS + _option_keys(entry))
        owners = [m.name for m in registry.METHOD_REGISTRY if key in _option_keys(m)]
        what = (f"a key of the {', '.join(owners)} method{'s' * (len(owners) > 1)}, not of "
                f"{name}" if owners else f"unknown key for the {name} method")
        raise SceneError(path, f"method.{key}", f"{what}; {name} takes: {takes}")
    return Method(**kw, options=options)


def _option_keys(entry) -> tuple:
    """The [method] keys of a method's own options, in field order."""
    return tuple(f.name for f in dataclasses.fields(entry.options_class))


def _cross_checks(path, scene: Scene):
    agg = scene.aggregation
    factors = [EFFICIENCY_BY_NAME[f] for f in agg.efficiency] if agg is not None else []
    if agg is not None and agg.reads_binder and not scene.bivariate:
        raise SceneError(path, "aggregation.efficiency",
                         f"{', '.join(agg.efficiency)} efficiency depends on binder, but the scene "
                         "has none: expected [binder_injection] or initial.binder_fraction > 0")
    fields = KERNEL_BY_NAME[agg.kernel].cell_fields if agg is not None else ()
    if (("granular_temperature" in fields or "solids_fraction" in fields)
            and scene.domain.type == "well-mixed"):
        if scene.domain.granular_temperature is None or scene.domain.solids_fraction is None:
            raise SceneError(path, "domain.granular_temperature",
                             f"the {agg.kernel} kernel needs granular_temperature (m2/s2) and "
                             "solids_fraction of the well-mixed domain")
    for f in factors:
        if (f.uses_collision_velocity and scene.domain.type == "well-mixed"
                and scene.domain.collision_velocity is None
                and scene.domain.granular_temperature is None):
            raise SceneError(path, "domain.collision_velocity",
                             f"the {f.name} efficiency needs collision_velocity (m/s) or "
                             "granular_temperature (m2/s2)")
    if (scene.domain.type == "well-mixed" and scene.initial.number_density == 0.0
            and scene.binder_injection is None):
        raise SceneError(path, "initial.number_density",
                         "expected a positive number density (or a binder injection)")
    entry = registry.METHODS[scene.method.name]
    if (not entry.integrated and scene.initial.number_density == 0.0
            and scene.initial.droplet_number_density == 0.0):
        raise SceneError(path, "initial.number_density",
                         f"the {scene.method.name} reference samples the particles present at "
                         "the start: expected a positive number_density or "
                         "droplet_number_density")
    for key, refusal in (spray.spray_refusals(scene, entry)
                         + drying_refusals(scene, registry.METHOD_REGISTRY)):
        raise SceneError(path, key, refusal)
    if not entry.integrated and scene.domain.type != "well-mixed":
        raise SceneError(path, "method.name",
                         f"the {scene.method.name} reference runs well-mixed scenes: expected "
                         f"{' or '.join(registry.MOMENT_METHODS)} for an openfoam domain")


# ------------------------------------------------------------------------------ bundled scenes
def bundled_scenes() -> dict[str, Path]:
    """Bundled scene names -> paths (package data ``pbe_cfd/scenes/*.toml``)."""
    root = resources.files("pbe_cfd") / "scenes"
    return {Path(p.name).stem: Path(str(p)) for p in root.iterdir() if p.name.endswith(".toml")}


def resolve_scene_path(source) -> Path:
    """A scene file path, or the path of a bundled scene of that name."""
    path = Path(source)
    if path.exists():
        return path
    bundled = bundled_scenes()
    if str(source) in bundled:
        return bundled[str(source)]
    raise SceneError(source, None,
                     "no such file, and not a bundled scene (expected a TOML path or one of: "
                     + ", ".join(sorted(bundled)) + ")")


def describe(scene: Scene) -> dict[str, Any]:
    """The scene as plain data (for summary.json); the method as its flat ``[method]`` table
    (the common keys, then the method's own, with the values in effect)."""
    out = dataclasses.asdict(scene) | {"raw": None}
    if out["output"] is None:          # no [output] table: the echo without its key
        del out["output"]
    if out["drying"] is not None:      # the drying's inputs at the scene's: without the keys
        for key in ("slip_velocity_source", "air_temperature_source"):
            if out["drying"][key] == "scene":
                del out["drying"][key]
    options = scene.method.options
    # the values in effect where an option is set by others when unset (``in_effect``)
    own = options.in_effect() if hasattr(options, "in_effect") else out["method"]["options"]
    out["method"].pop("options")
    out["method"] = out["method"] | own
    return out
