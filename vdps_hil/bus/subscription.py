"""Fan-out on the bus: a :class:`Subscription` is a bounded queue of events (``RawCan``,
``RawSerial``, ``Sample``) from one or more publishers (adapters) to one listener.

Never blocking the reader: an overflow drops the event for that subscription only and counts
it (on the subscription, per source; the publishing adapter counts it too, as its source's
``queue_overflow``). A subscription may be attached to many adapters (fan-in to one recorder).
"""

from __future__ import annotations

import threading
from collections import deque

from vdps_hil.bus.raw import RawCan, RawSerial
from vdps_hil.bus.samples import Sample

__all__ = ["Event", "Subscription"]

Event = RawCan | RawSerial | Sample
"""What a subscription carries."""


class Subscription:
    """A bounded queue from one or more adapters to one listener.

    ``put`` never blocks: when ``maxsize`` events are waiting the new one is dropped and
    counted (``overflows``, and per source in ``overflows_by_source``). ``raw`` / ``samples``
    select which events this listener wants. ``drain(max_n)`` returns what is waiting (oldest
    first); ``wait(timeout_s)`` sleeps until something was put (or the timeout passed).
    """

    def __init__(self, name: str = "listener", maxsize: int = 100_000, *, raw: bool = True,
                 samples: bool = True):
        if maxsize < 1:
            raise ValueError("maxsize must be >= 1")
        self.name, self.maxsize = name, int(maxsize)
        self.raw, self.samples = bool(raw), bool(samples)
        self._q: deque = deque()
        self._event = threading.Event()
        self.overflows = 0
        self.overflows_by_source: dict[str, int] = {}
        self.delivered = 0
        self.high_water = 0

    def wants(self, ev: Event) -> bool:
        return self.samples if isinstance(ev, Sample) else self.raw

    def put(self, ev: Event) -> bool:
        q = self._q
        n = len(q)
        if n >= self.maxsize:
            self.overflows += 1
            src = ev.source
            self.overflows_by_source[src] = self.overflows_by_source.get(src, 0) + 1
            return False
        q.append(ev)
        if n == 0:
            self._event.set()
        elif n >= self.high_water:
            self.high_water = n + 1
        return True

    def drain(self, max_n: int | None = None) -> list:
        q = self._q
        out = []
        pop = q.popleft
        n = len(q) if max_n is None else min(max_n, len(q))
        for _ in range(n):
            out.append(pop())
        self.delivered += len(out)
        return out

    def wait(self, timeout_s: float) -> bool:
        if self._q:
            return True
        self._event.clear()
        if self._q:  # put between the check and the clear
            return True
        return self._event.wait(timeout_s)

    def __len__(self) -> int:
        return len(self._q)
