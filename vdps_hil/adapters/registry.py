"""Explicit adapter registry: name -> class, loaded lazily; third parties add entry points.

Built-in names are listed in :data:`ADAPTERS` as ``(module, class)`` strings so importing the
registry does not import python-can or pyserial. A third-party package adds adapters through
the entry point group ``vdps_hil.adapters`` (``name = "package.module:Class"``); built-in
names win on a clash. Every class must derive from :class:`vdps_hil.adapters.base.Adapter`.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points

from vdps_hil.adapters.base import Adapter, AdapterError

ENTRY_POINT_GROUP = "vdps_hil.adapters"

ADAPTERS: dict[str, tuple[str, str]] = {
    "can": ("vdps_hil.adapters.can_adapter", "CanAdapter"),
    "can-file": ("vdps_hil.adapters.can_adapter", "CanFileAdapter"),
    "serial": ("vdps_hil.adapters.serial_adapter", "SerialAdapter"),
    "serial-file": ("vdps_hil.adapters.serial_adapter", "SerialFileAdapter"),
    "nmea": ("vdps_hil.adapters.nmea_adapter", "NmeaAdapter"),
    "nmea-file": ("vdps_hil.adapters.nmea_adapter", "NmeaTextFileAdapter"),
    "imu": ("vdps_hil.adapters.imu_adapter", "ImuAdapter"),
    "imu-file": ("vdps_hil.adapters.imu_adapter", "ImuFileAdapter"),
}
"""Built-in adapters: name -> (module, class)."""


def _third_party() -> dict[str, object]:
    try:
        return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}
    except Exception:  # noqa: BLE001 - broken metadata must not break the built-ins
        return {}


def available() -> list[str]:
    """Every adapter name: built-in first, then third-party entry points."""
    names = list(ADAPTERS)
    names += sorted(n for n in _third_party() if n not in ADAPTERS)
    return names


def adapter_class(name: str) -> type[Adapter]:
    """The class registered under ``name`` (AdapterError, one line, when unknown)."""
    if name in ADAPTERS:
        module, attr = ADAPTERS[name]
        cls = getattr(importlib.import_module(module), attr)
    else:
        ep = _third_party().get(name)
        if ep is None:
            raise AdapterError(f"unknown adapter {name!r} (known: {', '.join(available())})")
        try:
            cls = ep.load()
        except Exception as e:  # noqa: BLE001
            raise AdapterError(f"adapter {name!r} from entry point {ep.value} does not load: "
                               f"{type(e).__name__}: {e}") from None
    if not (isinstance(cls, type) and issubclass(cls, Adapter)):
        raise AdapterError(f"adapter {name!r} is not a vdps_hil.adapters.base.Adapter")
    return cls


def create(name: str, *args, **kwargs) -> Adapter:
    """Instantiate the adapter registered under ``name``."""
    return adapter_class(name)(*args, **kwargs)
