"""python-can's MF4 backend (asammdf, pandas) loads only when an MF4 reader or writer is made
(``vdps_hil.deferred_imports``), and python-can's MF4 API works as before. Each case runs in a
fresh interpreter: the deferral acts on the first ``import can`` of a process."""

from __future__ import annotations

import json
import subprocess
import sys

READ = """
import json, sys
{first}
import vdps_hil, can
before = "asammdf" in sys.modules
n = sum(1 for _ in can.LogReader(sys.argv[1]))
print(json.dumps({{"before": before, "after": "asammdf" in sys.modules, "frames": n}}))
"""


def _run(code: str, *args: str) -> dict:
    p = subprocess.run([sys.executable, "-P", "-c", code, *args], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_can_loads_without_asammdf_and_a_log_reader_reads_an_mf4_as_before(real_data):
    log = str(real_data / "css_canedge_gnss_imu_mf4" / "gnss1.MF4")
    deferred = _run(READ.format(first=""), log)
    eager = _run(READ.format(first="import asammdf"), log)  # asammdf first: nothing is deferred
    assert deferred["before"] is False and deferred["after"] is True
    assert eager["before"] is True
    assert deferred["frames"] == eager["frames"] > 1000


def test_python_can_s_mf4_writer_and_reader_classes_work_without_a_call_of_ours(tmp_path):
    """``can.Logger("x.mf4")`` (the writer class held in python-can's table since ``import
    can``), then ``can.MF4Reader`` itself (the class ``can`` exports), each the first MF4 object
    of its process."""
    code = """
import json, sys
import vdps_hil, can
path, how = sys.argv[1], sys.argv[2]
if how == "logger":
    with can.Logger(path) as w:
        for i in range(5):
            w.on_message_received(can.Message(timestamp=1.0 + i, arbitration_id=0x100 + i, data=bytes([i] * 8)))
else:
    r = can.MF4Reader(path)
    print(json.dumps({"ids": [m.arbitration_id for m in r]}))
"""
    path = str(tmp_path / "w.mf4")
    subprocess.run([sys.executable, "-P", "-c", code, path, "logger"], check=True, timeout=120)
    assert _run(code, path, "reader")["ids"] == [0x100, 0x101, 0x102, 0x103, 0x104]


def test_the_can_file_adapter_and_an_import_of_asammdf_elsewhere(real_data):
    """The adapter reads an MF4 with asammdf deferred; an ``import asammdf`` by anyone but
    python-can's first run of its MF4 module is never hidden."""
    code = """
import json, sys
import vdps_hil, can
from vdps_hil.adapters.can_adapter import CanFileAdapter
before = "asammdf" in sys.modules
a = CanFileAdapter("gnss", sys.argv[1]); a.open(); a.close()
after = "asammdf" in sys.modules
import asammdf.blocks.options
print(json.dumps({"before": before, "after": after}))
"""
    got = _run(code, str(real_data / "css_canedge_gnss_imu_mf4" / "gnss2.MF4"))
    assert got == {"before": False, "after": True}
    got = _run("import json, vdps_hil, can, asammdf; print(json.dumps({'ok': asammdf.MDF is not None}))")
    assert got == {"ok": True}


def test_only_the_thread_running_python_can_s_module_is_answered_not_installed():
    """The hiding follows the thread that runs ``can.io.mf4`` (another thread may import asammdf at
    that moment): asked from this thread while another holds it, asammdf imports; asked while this
    thread holds it, "not installed"."""
    code = """
import _thread, json
import vdps_hil.deferred_imports as d
d._state["hiding"] = _thread.get_ident()
try:
    import asammdf.blocks.options
    mine = "imported"
except ModuleNotFoundError as e:
    mine = "not installed" if "deferred" in str(e) else repr(e)
d._state["hiding"] = -1  # another thread's
import asammdf
other = "imported" if asammdf.MDF is not None else "?"
print(json.dumps({"mine": mine, "other": other}))
"""
    assert _run(code) == {"mine": "not installed", "other": "imported"}


def test_a_python_can_without_the_expected_classes_gets_asammdf_at_once():
    """Where python-can's MF4 module has no MF4Reader and MF4Writer classes (another version),
    nothing could make asammdf available later: the module runs again at once with it."""
    code = """
import json, sys, types
import vdps_hil.deferred_imports as d

class FakeLoader:  # a module body that imports asammdf, as python-can's does
    def create_module(self, spec):
        return None
    def exec_module(self, module):
        try:
            import asammdf
            module.runs = getattr(module, "runs", []) + ["with asammdf"]
        except ModuleNotFoundError:
            module.runs = getattr(module, "runs", []) + ["without"]

m = types.ModuleType("can.io.mf4")
d._DeferringLoader(FakeLoader()).exec_module(m)
print(json.dumps({"runs": m.runs, "released": d._state["released"]}))
"""
    assert _run(code) == {"runs": ["without", "with asammdf"], "released": True}
