"""python-can's MF4 backend (asammdf, pandas) loads only when an MF4 file is opened
(``vdps_hil.deferred_imports``). Each case runs in a fresh interpreter: the deferral acts on the
first ``import can`` of a process."""

from __future__ import annotations

import json
import subprocess
import sys

READ = """
import json, sys
{first}
import vdps_hil, can
before = "asammdf" in sys.modules
{enable}
n = sum(1 for _ in can.LogReader(sys.argv[1]))
print(json.dumps({{"before": before, "after": "asammdf" in sys.modules, "frames": n}}))
"""


def _run(code: str, *args: str) -> dict:
    p = subprocess.run([sys.executable, "-P", "-c", code, *args], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_can_loads_without_asammdf_and_an_mf4_reads_the_same_once_enabled(real_data):
    log = str(real_data / "css_canedge_gnss_imu_mf4" / "gnss1.MF4")
    deferred = _run(READ.format(first="", enable="from vdps_hil.deferred_imports import mf4_support; "
                                                  "assert mf4_support()"), log)
    eager = _run(READ.format(first="import asammdf", enable=""), log)  # asammdf first: nothing deferred
    assert deferred["before"] is False and deferred["after"] is True
    assert eager["before"] is True
    assert deferred["frames"] == eager["frames"] > 1000


def test_the_can_file_adapter_enables_mf4_itself(real_data):
    code = """
import json, sys
import vdps_hil, can
from vdps_hil.adapters.can_adapter import CanFileAdapter
before = "asammdf" in sys.modules
a = CanFileAdapter("gnss", sys.argv[1]); a.open(); a.close()
print(json.dumps({"before": before, "after": "asammdf" in sys.modules}))
"""
    got = _run(code, str(real_data / "css_canedge_gnss_imu_mf4" / "gnss2.MF4"))
    assert got == {"before": False, "after": True}


def test_asammdf_imported_elsewhere_is_not_hidden(tmp_path):
    """Only can.io.mf4's first run is answered "not installed"; an import of asammdf by anyone
    else works, and python-can's MF4 writer works after mf4_support."""
    code = """
import json, sys
import vdps_hil, can
import asammdf
from vdps_hil.deferred_imports import mf4_support
assert mf4_support()
path = sys.argv[1]
with can.Logger(path) as w:
    for i in range(5):
        w.on_message_received(can.Message(timestamp=1.0 + i, arbitration_id=0x100 + i, data=bytes([i] * 8)))
ids = [m.arbitration_id for m in can.LogReader(path)]
print(json.dumps({"ids": ids}))
"""
    got = _run(code, str(tmp_path / "w.mf4"))
    assert got["ids"] == [0x100, 0x101, 0x102, 0x103, 0x104]
