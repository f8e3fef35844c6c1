"""Adapter registry: built-in names, third-party entry points (a real distribution's metadata
on sys.path), one-line errors."""

import pytest

from vdps_hil.adapters.base import Adapter, AdapterError
from vdps_hil.adapters.registry import ADAPTERS, adapter_class, available, create


def test_builtins_resolve_to_adapter_classes():
    for name in ADAPTERS:
        assert issubclass(adapter_class(name), Adapter)
    assert available()[: len(ADAPTERS)] == list(ADAPTERS)


def test_unknown_name_is_one_line():
    with pytest.raises(AdapterError) as e:
        adapter_class("teleport")
    assert "unknown adapter 'teleport'" in str(e.value) and "can" in str(e.value)


def test_third_party_entry_point(tmp_path, monkeypatch):
    pkg = tmp_path / "site"
    (pkg / "probe_adapter_pkg").mkdir(parents=True)
    (pkg / "probe_adapter_pkg" / "__init__.py").write_text(
        "from vdps_hil.adapters.serial_adapter import SerialAdapter\n"
        "class ProbeAdapter(SerialAdapter):\n    pass\n"
        "class NotAnAdapter:\n    pass\n")
    dist = pkg / "probe_adapter_pkg-0.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: probe-adapter-pkg\n"
                                   "Version: 0.0\n")
    (dist / "entry_points.txt").write_text(
        "[vdps_hil.adapters]\nprobe = probe_adapter_pkg:ProbeAdapter\n"
        "bogus = probe_adapter_pkg:NotAnAdapter\ncan = probe_adapter_pkg:ProbeAdapter\n")
    monkeypatch.syspath_prepend(str(pkg))
    assert "probe" in available()
    a = create("probe", "dev", "/dev/null", 9600)
    assert type(a).__name__ == "ProbeAdapter" and a.name == "dev"
    with pytest.raises(AdapterError, match="not a vdps_hil.adapters.base.Adapter"):
        adapter_class("bogus")
    assert adapter_class("can").__name__ == "CanAdapter"  # built-ins win
