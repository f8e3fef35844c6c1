"""Vehicle files: frozen parameter dataclasses with units in every field name, loaded from TOML.

Two kinds of file live in ``configs/vehicles/``:

* a **truth** file (``kind = "truth"``): everything the simulator needs, each number commented
  with where it comes from. Only the simulator reads it.
* a **model** file (``kind = "model"``): what the paper treats as known (geometry, springs and
  dampers of eq 14, unsprung masses, tire radius and inertia, sensor mounting) plus *priors* for
  the ten identified parameters (section 5.2), which differ from the truth. The estimator,
  identifier, predictor and workbench read only model files.

Loading uses :mod:`tomllib` (data only: nothing in a file can execute code); unknown or missing
keys, wrong types, non-finite numbers and numbers outside their physical range (:data:`RANGES`,
wide enough for any road vehicle from a city car to a heavy truck; every component of a
3-vector) are rejected with one-line :class:`VehicleFileError`, and so is a total mass that
leaves no sprung mass above the four unsprung ones. Identified parameters produce a new object
(``dataclasses.replace``), never a mutation.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, get_type_hints

from .chassis import PAPER_CHASSIS, Chassis

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"
VEHICLE_DIR = CONFIG_DIR / "vehicles"


class VehicleFileError(ValueError):
    """A vehicle file that cannot be used; the message is one line for the user."""


@dataclass(frozen=True)
class Geometry:
    l_f_m: float  # CG to front axle [m]
    l_r_m: float  # CG to rear axle [m]
    track_half_front_m: float  # t_f: half the front track [m]
    track_half_rear_m: float  # t_r: half the rear track [m]
    h_cg_m: float  # CG height above ground at design ride height [m]
    steer_ratio: float  # steering wheel angle / mean front road-wheel angle [-]

    @property
    def wheelbase_m(self) -> float:
        return self.l_f_m + self.l_r_m

    @property
    def static_stability_factor(self) -> float:
        """SSF = t_half / h_cg (mean half track)."""
        return 0.5 * (self.track_half_front_m + self.track_half_rear_m) / self.h_cg_m

    def corner_xy_m(self) -> tuple[tuple[float, float], ...]:
        """Body-frame (x, y) of corners 1..4 (FL, FR, RR, RL), ISO 8855 (y left)."""
        return ((self.l_f_m, self.track_half_front_m), (self.l_f_m, -self.track_half_front_m),
                (-self.l_r_m, -self.track_half_rear_m), (-self.l_r_m, self.track_half_rear_m))


@dataclass(frozen=True)
class Axle:
    """One axle's suspension corner (both corners equal). Eq 14:
    F = K_s H + D_s H' + m_u g with K_s = C1 exp(C2 (H - C3)), H the spring compression from
    free length = static_compression_m + susp_deflection_m."""

    spring_c1_npm: float  # C1 [N/m]
    spring_c2_per_m: float  # C2 [1/m]
    spring_c3_m: float  # C3 [m]
    static_compression_m: float  # spring compression at design ride height [m]
    damper_nspm: float  # D_s [N s/m]
    unsprung_mass_kg: float  # m_u per corner [kg]


@dataclass(frozen=True)
class Tire:
    rolling_radius_m: float  # r_i effective rolling radius [m]
    wheel_inertia_kgm2: float  # I_omega spin inertia of wheel + tire [kg m^2]
    vertical_stiffness_npm: float  # tire radial stiffness [N/m]


@dataclass(frozen=True)
class Mounting:
    """Sensor mounting in the vehicle frame (x fwd, y left, z up) relative to the CG."""

    imu_lever_arm_m: tuple[float, float, float]
    imu_rotation_rpy_rad: tuple[float, float, float]  # body -> sensor (roll, pitch, yaw)
    gnss_lever_arm_m: tuple[float, float, float]  # position reference antenna
    gnss_attitude_baseline_m: float  # antenna baseline length for attitude [m]


@dataclass(frozen=True)
class IdentifiedParams:
    """The ten parameters of section 5.2 (RLS eq 20-23)."""

    mass_kg: float  # m_tot, total vehicle mass incl. unsprung [kg]
    inertia_x_kgm2: float  # I_x sprung body about CG [kg m^2]
    inertia_y_kgm2: float
    inertia_z_kgm2: float
    tracking_stiffness_1_n: float  # C_lambda,i [N per unit slip ratio]
    tracking_stiffness_2_n: float
    tracking_stiffness_3_n: float
    tracking_stiffness_4_n: float
    cornering_stiffness_front_nprad: float  # C_alpha,f = C_alpha,1 + C_alpha,2 [N/rad]
    cornering_stiffness_rear_nprad: float  # C_alpha,r = C_alpha,3 + C_alpha,4 [N/rad]

    def as_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)

    @property
    def tracking_stiffness_n(self) -> tuple[float, float, float, float]:
        return (self.tracking_stiffness_1_n, self.tracking_stiffness_2_n,
                self.tracking_stiffness_3_n, self.tracking_stiffness_4_n)


PARAM_NAMES: tuple[str, ...] = tuple(f.name for f in fields(IdentifiedParams))


@dataclass(frozen=True)
class Vehicle:
    name: str
    kind: str  # "truth" or "model"
    description: str
    geometry: Geometry
    front: Axle
    rear: Axle
    tire: Tire
    mounting: Mounting
    params: IdentifiedParams  # truth values (truth file) or priors (model file)
    effects: dict = field(default_factory=dict)  # truth only: effect name -> {param: value}
    source_sha256: str = ""
    chassis: Chassis = PAPER_CHASSIS  # optional [chassis]: anti-roll bars, roll centres, Ackermann

    def axle(self, corner: int) -> Axle:
        """Axle of corner 0..3 (0-based FL, FR, RR, RL)."""
        return self.front if corner in (0, 1) else self.rear

    @property
    def unsprung_mass_total_kg(self) -> float:
        return 2.0 * (self.front.unsprung_mass_kg + self.rear.unsprung_mass_kg)

    @property
    def sprung_mass_kg(self) -> float:
        return self.params.mass_kg - self.unsprung_mass_total_kg

    def with_params(self, **changes: float) -> "Vehicle":
        """A new Vehicle with some identified parameters replaced (never mutates)."""
        return dataclasses.replace(self, params=dataclasses.replace(self.params, **changes))


RANGES: dict[str, tuple[float, float]] = {
    # geometry [m], [-]: CG to axle 0.05-10 m (wheelbase up to a heavy truck's), half track
    # 0.1-2 m, CG height 0.05-5 m, steering ratio 1-100 (module docstring)
    "l_f_m": (0.05, 10.0), "l_r_m": (0.05, 10.0),
    "track_half_front_m": (0.1, 2.0), "track_half_rear_m": (0.1, 2.0),
    "h_cg_m": (0.05, 5.0), "steer_ratio": (1.0, 100.0),
    # suspension corner (eq 14): spring C1 [N/m], progression C2 [1/m] (0: linear; 50/m would
    # multiply the stiffness by e^5 over 10 cm), C3 and static compression [m], damper
    # [N s/m] (0: none), unsprung mass per corner [kg]
    "spring_c1_npm": (100.0, 1.0e7), "spring_c2_per_m": (-50.0, 50.0), "spring_c3_m": (-1.0, 1.0),
    "static_compression_m": (0.0, 1.0), "damper_nspm": (0.0, 1.0e6), "unsprung_mass_kg": (1.0, 2000.0),
    # tire: rolling radius [m], spin inertia [kg m^2], radial stiffness [N/m]
    "rolling_radius_m": (0.1, 2.0), "wheel_inertia_kgm2": (0.01, 500.0),
    "vertical_stiffness_npm": (1.0e4, 1.0e8),
    # sensor mounting: lever arms [m] per component, rotation [rad] per angle, antenna
    # baseline [m] (0: a single antenna, no attitude)
    "imu_lever_arm_m": (-20.0, 20.0), "imu_rotation_rpy_rad": (-math.pi, math.pi),
    "gnss_lever_arm_m": (-20.0, 20.0), "gnss_attitude_baseline_m": (0.0, 100.0),
    # the ten identified parameters (priors, or truth): mass [kg], inertias [kg m^2],
    # tracking stiffnesses [N per unit slip], cornering stiffnesses per axle [N/rad]
    "mass_kg": (50.0, 1.0e5), "inertia_x_kgm2": (1.0, 1.0e7), "inertia_y_kgm2": (1.0, 1.0e7),
    "inertia_z_kgm2": (1.0, 1.0e7),
    **{f"tracking_stiffness_{i}_n": (100.0, 1.0e8) for i in range(1, 5)},
    "cornering_stiffness_front_nprad": (100.0, 1.0e8), "cornering_stiffness_rear_nprad": (100.0, 1.0e8),
}
"""Physical range [lo, hi] of every number of a vehicle file, by field name (units in the name)."""

_SECTIONS = {"geometry": Geometry, "front": Axle, "rear": Axle, "tire": Tire,
             "mounting": Mounting, "params": IdentifiedParams}


def _build(cls, table: Any, where: str):
    if not isinstance(table, dict):
        raise VehicleFileError(f"{where}: expected a table")
    hints = get_type_hints(cls)
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(table) - set(names))
    if unknown:
        raise VehicleFileError(f"{where}: unknown key {unknown[0]!r}")
    missing = [n for n in names if n not in table]
    if missing:
        raise VehicleFileError(f"{where}: missing key {missing[0]!r}")
    kwargs = {}
    for n in names:
        v, t = table[n], hints[n]
        if t is float:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise VehicleFileError(f"{where}.{n}: expected a finite number, got {v!r}")
            kwargs[n] = float(v)
        else:  # 3-vectors
            if (not isinstance(v, list) or len(v) != 3
                    or not all(isinstance(e, (int, float)) and not isinstance(e, bool) and math.isfinite(e) for e in v)):
                raise VehicleFileError(f"{where}.{n}: expected a list of 3 finite numbers")
            kwargs[n] = tuple(float(e) for e in v)
        check_range(n, kwargs[n], where)
    return cls(**kwargs)


def check_range(name: str, value, where: str) -> None:
    """``value`` (a number or each component of a vector) inside ``RANGES[name]``, else
    :class:`VehicleFileError` (one line, naming ``where``)."""
    lo, hi = RANGES.get(name, (-math.inf, math.inf))
    for x in value if isinstance(value, tuple) else (value,):
        if not lo <= x <= hi:
            raise VehicleFileError(f"{where}.{name} = {x:g} is outside its physical range "
                                   f"[{lo:g}, {hi:g}]")


def parse_vehicle(text: str, origin: str = "<string>") -> Vehicle:
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise VehicleFileError(f"{origin}: malformed TOML: {e}") from None
    allowed = {"name", "kind", "description", "effects", "chassis", *_SECTIONS}
    unknown = sorted(set(doc) - allowed)
    if unknown:
        raise VehicleFileError(f"{origin}: unknown key {unknown[0]!r}")
    kind = doc.get("kind")
    if kind not in ("truth", "model"):
        raise VehicleFileError(f"{origin}: kind must be \"truth\" or \"model\", got {kind!r}")
    for s in _SECTIONS:
        if s not in doc:
            raise VehicleFileError(f"{origin}: missing table [{s}]")
    built = {s: _build(cls, doc[s], f"{origin}[{s}]") for s, cls in _SECTIONS.items()}
    effects = doc.get("effects", {})
    if not isinstance(effects, dict):
        raise VehicleFileError(f"{origin}[effects]: expected a table")
    if kind == "model" and effects:
        raise VehicleFileError(f"{origin}: a model file may not carry [effects] (truth only)")
    unsprung = 2.0 * (built["front"].unsprung_mass_kg + built["rear"].unsprung_mass_kg)
    if built["params"].mass_kg <= unsprung:
        raise VehicleFileError(f"{origin}[params].mass_kg = {built['params'].mass_kg:g} leaves no sprung "
                               f"mass above the four unsprung masses ({unsprung:g} kg)")
    return Vehicle(name=str(doc.get("name", Path(origin).stem)), kind=kind,
                   description=str(doc.get("description", "")), effects=effects,
                   source_sha256=hashlib.sha256(text.encode()).hexdigest(),
                   chassis=_build_chassis(doc.get("chassis", {}), f"{origin}[chassis]"), **built)


def _build_chassis(table: Any, where: str) -> Chassis:
    """The optional ``[chassis]`` table (``model.chassis``): every key optional, a missing one
    at the paper's value."""
    if not isinstance(table, dict):
        raise VehicleFileError(f"{where}: expected a table")
    names = [f.name for f in fields(Chassis)]
    unknown = sorted(set(table) - set(names))
    if unknown:
        raise VehicleFileError(f"{where}: unknown key {unknown[0]!r}")
    for n, v in table.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise VehicleFileError(f"{where}.{n}: expected a finite number, got {v!r}")
    try:
        return Chassis(**{n: float(v) for n, v in table.items()})
    except ValueError as e:
        raise VehicleFileError(f"{where}: {e}") from None


def resolve_vehicle_path(name_or_path: str | Path) -> Path:
    """A path, or a bare name looked up as ``configs/vehicles/<name>.toml``."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        return p
    return VEHICLE_DIR / f"{name_or_path}.toml"


def load_vehicle(name_or_path: str | Path, expect_kind: str | None = None) -> Vehicle:
    path = resolve_vehicle_path(name_or_path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise VehicleFileError(f"cannot read vehicle file {path}: {e.__class__.__name__}: {e}") from None
    v = parse_vehicle(text, str(path))
    if expect_kind is not None and v.kind != expect_kind:
        raise VehicleFileError(f"{path}: is a {v.kind} file, a {expect_kind} file is needed here")
    return v
