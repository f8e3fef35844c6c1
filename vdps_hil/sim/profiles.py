"""Sensor profiles (``configs/profiles/*.toml``): rates, noise and realistic error switches of
the simulated sensors. ``table1`` is the paper's Table 1 exactly as printed; ``table1-susp1k``
puts the suspension sensors at 1 kHz (evidence in that file).

All values are converted to SI here (deg -> rad, deg/s -> rad/s). Loading uses tomllib; unknown
or missing keys, wrong types and non-positive rates are one-line :class:`ProfileError`.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path

from vdps_hil.model.params import CONFIG_DIR

PROFILE_DIR = CONFIG_DIR / "profiles"
ATTITUDE_SENTENCES = ("PASHR", "HPR", "PTNL_AVR")


class ProfileError(ValueError):
    """A sensor profile that cannot be used (one-line message)."""


@dataclass(frozen=True)
class GnssProfile:
    rate_hz: float
    attitude_sigma_rad: float
    pos_sigma_h_m: float
    pos_sigma_v_m: float
    attitude_sentence: str
    baud: int
    latency_s: float
    gauss_markov_tau_s: float  # 0: white position noise; > 0: first-order Gauss-Markov
    fix_quality: int


@dataclass(frozen=True)
class SuspensionProfile:
    rate_hz: float
    sigma_m: float


@dataclass(frozen=True)
class ImuProfile:
    rate_hz: float
    accel_sigma_mps2: float
    gyro_sigma_radps: float
    baud: int
    scale_factor_ppm: float
    misalignment_rad: float


@dataclass(frozen=True)
class TachometerProfile:
    rate_hz: float
    sigma_radps: float


@dataclass(frozen=True)
class TorqueProfile:
    rate_hz: float
    sigma_nm: float


@dataclass(frozen=True)
class SteeringProfile:
    rate_hz: float
    sigma_rad: float


@dataclass(frozen=True)
class SensorProfile:
    name: str
    description: str
    gnss: GnssProfile
    suspension: SuspensionProfile
    imu: ImuProfile
    tachometer: TachometerProfile
    wheel_torque: TorqueProfile
    steering: SteeringProfile
    quantise_dbc: bool

    def zero_noise(self) -> "SensorProfile":
        """The same rates with every noise and error source off ("noise-free" sensors)."""
        import dataclasses as dc
        return dc.replace(
            self, name=self.name + "-zero-noise",
            gnss=dc.replace(self.gnss, attitude_sigma_rad=0.0, pos_sigma_h_m=0.0, pos_sigma_v_m=0.0),
            suspension=dc.replace(self.suspension, sigma_m=0.0),
            imu=dc.replace(self.imu, accel_sigma_mps2=0.0, gyro_sigma_radps=0.0,
                           scale_factor_ppm=0.0, misalignment_rad=0.0),
            tachometer=dc.replace(self.tachometer, sigma_radps=0.0),
            wheel_torque=dc.replace(self.wheel_torque, sigma_nm=0.0),
            steering=dc.replace(self.steering, sigma_rad=0.0))


# raw key in the file -> (dataclass field, conversion factor to SI)
_CONVERT = {
    "attitude_sigma_deg": ("attitude_sigma_rad", math.pi / 180.0),
    "gyro_sigma_degps": ("gyro_sigma_radps", math.pi / 180.0),
    "sigma_degps": ("sigma_radps", math.pi / 180.0),
    "misalignment_mrad": ("misalignment_rad", 1e-3),
}


_MAX_FIGURE = 1e6
"""Largest value of a profile number (sigmas, latencies in s, ...; the shipped profiles stay
below 1e3 but for the baud rates): 1e300 passed the finite check and overflowed downstream."""
_RANGES = {"rate_hz": (0.0, 1e5), "baud": (1.0, 1e8)}
"""Fields with their own range: a sample rate up to 100 kHz, a serial line of 1 Bd to 100 MBd
(0 Bd was an internal error, a rate of 1e300 Hz a division by a zero period)."""


def _section(cls, table, where: str):
    if not isinstance(table, dict):
        raise ProfileError(f"{where}: expected a table")
    want = {f.name: f.type for f in fields(cls)}
    got = {}
    for key, value in table.items():
        name, factor = _CONVERT.get(key, (key, 1.0))
        if name not in want:
            raise ProfileError(f"{where}: unknown key {key!r}")
        typ = want[name]
        if typ in ("str", str):
            if not isinstance(value, str):
                raise ProfileError(f"{where}.{key}: expected a string")
            got[name] = value
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise ProfileError(f"{where}.{key}: expected a finite non-negative number, got {value!r}")
        lo, hi = _RANGES.get(name, (0.0, _MAX_FIGURE))
        if not lo <= value <= hi:
            raise ProfileError(f"{where}.{key}: {value!r} is outside [{lo:g}, {hi:g}]")
        got[name] = int(value) if typ in ("int", int) else float(value) * factor
    missing = sorted(set(want) - set(got))
    if missing:
        raise ProfileError(f"{where}: missing key for {missing[0]!r}")
    if "rate_hz" in got and got["rate_hz"] <= 0:
        raise ProfileError(f"{where}.rate_hz: must be positive")
    return cls(**got)


def parse_profile(text: str, origin: str = "<string>") -> SensorProfile:
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ProfileError(f"{origin}: malformed TOML: {e}") from None
    sections = {"gnss": GnssProfile, "suspension": SuspensionProfile, "imu": ImuProfile,
                "tachometer": TachometerProfile, "wheel_torque": TorqueProfile,
                "steering": SteeringProfile}
    unknown = sorted(set(doc) - {"name", "description", "quantisation", *sections})
    if unknown:
        raise ProfileError(f"{origin}: unknown key {unknown[0]!r}")
    for s in sections:
        if s not in doc:
            raise ProfileError(f"{origin}: missing table [{s}]")
    built = {s: _section(c, doc[s], f"{origin}[{s}]") for s, c in sections.items()}
    if built["gnss"].attitude_sentence not in ATTITUDE_SENTENCES:
        raise ProfileError(f"{origin}[gnss].attitude_sentence: one of {', '.join(ATTITUDE_SENTENCES)}")
    q = doc.get("quantisation", {})
    if not isinstance(q, dict) or set(q) - {"dbc"} or not isinstance(q.get("dbc", False), bool):
        raise ProfileError(f"{origin}[quantisation]: only the boolean key 'dbc' is allowed")
    return SensorProfile(name=str(doc.get("name", Path(origin).stem)),
                         description=str(doc.get("description", "")),
                         quantise_dbc=bool(q.get("dbc", False)), **built)


def available_profiles() -> list[str]:
    return sorted(p.stem for p in PROFILE_DIR.glob("*.toml"))


def load_profile(name_or_path: str | Path) -> SensorProfile:
    p = Path(name_or_path)
    if p.suffix != ".toml":
        p = PROFILE_DIR / f"{name_or_path}.toml"
        if not p.exists():
            raise ProfileError(f"unknown sensor profile {str(name_or_path)!r} "
                               f"(available: {', '.join(available_profiles())})")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ProfileError(f"cannot read sensor profile {p}: {e}") from None
    return parse_profile(text, str(p))
