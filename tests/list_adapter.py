"""A minimal real Adapter subclass for the tests of the adapter base class, its health and the
bus plumbing it uses (tests/test_adapter_base.py, test_adapter_health.py, test_bus_*.py)."""

from vdps_hil.adapters.base import Adapter, DeviceLost, EndOfInput
from vdps_hil.bus.raw import RawSerial
from vdps_hil.bus.samples import Sample

NS = 1_000_000_000


class ListAdapter(Adapter):
    """A minimal real subclass: payloads come from a list; decoding turns an int into a
    sample (or raises for the string 'boom')."""

    transport = "test"

    def __init__(self, items, *, fail_open_times=0, lose_at=None, **kw):
        super().__init__("src", "list", **kw)
        self.items = list(items)
        self.fail_open_times = fail_open_times
        self.lose_at = set(lose_at or ())
        self.opens = 0

    def _open(self):
        self.opens += 1
        if self.fail_open_times > 0:
            self.fail_open_times -= 1
            raise DeviceLost("not there")

    def _close(self):
        pass

    def _read(self, timeout_s):
        if not self.items:
            raise EndOfInput()
        item = self.items.pop(0)
        if item in self.lose_at:
            self.lose_at.discard(item)
            raise DeviceLost("unplugged")
        return [item]

    def _raw(self, t_ns, wall, payload):
        return RawSerial(t_ns, wall, self.name, repr(payload).encode())

    def _decode(self, t_ns, payload):
        v = payload
        if v == "boom":
            raise RuntimeError("decoder bug")
        return [Sample(t_ns=t_ns, source=self.name, kind="k", fields={"seq_counter": float(v)})]


def drain_all(a):
    while True:
        try:
            a.poll(0.0)
        except EndOfInput:
            return
