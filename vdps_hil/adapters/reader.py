"""Device readers that cannot be starved: what drains a device while the logger decodes, writes
and estimates elsewhere (``Adapter.start_reader``, used by ``app.session.LogSession``).

Two kinds, one interface (``give``, ``take``, ``stop``, ``fileno``):

* :class:`~vdps_hil.adapters.fdreader.FdReader` -- a device with a file descriptor (serial
  ports, pseudo-terminals, slcan adapters): a process of its own reads and stamps the bytes
  (``adapters.fdreader``);
* :class:`ThreadReader` -- anything else python-can or pyserial reads (``virtual``, ``pcan``,
  ``socket://`` ...): a thread calls the adapter's ``_read``, stamps what it returns with the
  adapter's clock and appends it to a bounded queue; ``_read`` waits in python-can's or
  pyserial's blocking call, where the GIL is released.

``take()`` returns the records in arrival order: ``(DATA, t_ns, payload)`` (a thread reader's
payloads are the adapter's: ``can.Message`` or bytes; a process reader's are bytes),
``(LOST, t_ns, reason)``, ``(OVERFLOW, t_ns, (n, bytes))`` (the bounded buffer was full: ``n``
chunks or frames dropped) and ``(ERROR, t_ns, reason)`` (a read failed and was retried).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any, Callable, Sequence

from vdps_hil.adapters.fdreader import DATA, LOST, OVERFLOW, FdReader

__all__ = ["ThreadReader", "FdReader", "DATA", "LOST", "OVERFLOW", "ERROR"]

ERROR = 3


class ThreadReader:
    """A thread draining ``read(timeout_s) -> [(t_ns | None, payload)]`` into a bounded queue.

    ``read`` raises ``lost`` exceptions when the device vanished (the thread then waits for
    :meth:`give`), ``end`` at the end of the input (the thread ends), and OSError/ValueError for
    a failed read (reported as ERROR, retried). ``None`` times are stamped with ``now()`` as the
    read returns. Beyond ``max_items`` waiting payloads, new ones are dropped and counted.
    """

    def __init__(self, name: str, read: Callable[[float], Sequence[tuple[int | None, Any]]],
                 now: Callable[[], int], *, lost: tuple = (), end: tuple = (),
                 max_items: int = 2_000_000, poll_s: float = 0.05):
        self.name = name
        self._read, self._now = read, now
        self._lost, self._end = tuple(lost), tuple(end)
        self.max_items = int(max_items)
        self.poll_s = float(poll_s)
        self._q: deque = deque()
        self._n = 0  # payloads waiting (the queue also holds events)
        self._go = threading.Event()
        self._go.set()
        self._stop = threading.Event()
        self._drop_n = 0
        self._drop_t = 0
        self._thread = threading.Thread(target=self._loop, name=f"reader-{name}", daemon=True)
        self._thread.start()

    def fileno(self):
        return None

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def give(self, fd=None) -> None:
        """The device is open again: resume reading."""
        self._go.set()

    def _loop(self) -> None:
        q = self._q
        while not self._stop.is_set():
            if not self._go.is_set():
                self._go.wait(self.poll_s)
                continue
            try:
                items = self._read(self.poll_s)
            except self._lost as e:
                self._go.clear()
                q.append((LOST, self._now(), str(e).splitlines()[0] if str(e) else "device lost"))
                continue
            except self._end:
                q.append((LOST, self._now(), "end of input"))
                return
            except (OSError, ValueError) as e:
                q.append((ERROR, self._now(), str(e).splitlines()[0] if str(e) else type(e).__name__))
                time.sleep(self.poll_s)
                continue
            if not items:
                continue
            t = None
            if len(items) + self._n > self.max_items:
                if not self._drop_n:
                    self._drop_t = self._now()
                self._drop_n += len(items)
                continue
            if self._drop_n:
                q.append((OVERFLOW, self._drop_t, (self._drop_n, 0)))
                self._drop_n = 0
            for t_ns, payload in items:
                if t_ns is None:
                    if t is None:
                        t = self._now()
                    t_ns = t
                q.append((DATA, t_ns, payload))
            self._n += len(items)

    def take(self, max_items: int = 1 << 20) -> list:
        q = self._q
        out = []
        pop = q.popleft
        n = min(len(q), max_items)
        for _ in range(n):
            out.append(pop())
        self._n -= sum(1 for r in out if r[0] == DATA)
        return out

    def stop(self, timeout_s: float = 5.0) -> list:
        self._stop.set()
        self._go.set()
        self._thread.join(timeout_s)
        out = self.take(len(self._q) + 1)
        if self._drop_n:
            out.append((OVERFLOW, self._drop_t, (self._drop_n, 0)))
            self._drop_n = 0
        return out

    def close(self) -> None:
        self.stop()
