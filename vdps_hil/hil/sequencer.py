"""The bench pipeline's input sequencer: the IMU (the estimator's input) ahead of the measurements
of the same instant (``hil.node``'s docstring, "Sequencing")."""

from __future__ import annotations

import heapq

__all__ = ["InputSequencer"]


class InputSequencer:
    """Hands samples to the system in the order its estimator needs: the IMU (the EKF's input)
    ahead of the measurements (module docstring, "Sequencing").

    ``push(item, t_ns, kind, now_ns)`` and ``expire(now_ns)`` return the items released, in
    order; ``flush()`` releases the rest. A measurement with ``t_ns`` at or before the newest IMU
    sample's time goes at once; a later one is held until an IMU sample at or after its time
    arrives (held ones leave in ``t_ns`` order, before that IMU sample), or until it has waited
    ``max_hold_s`` of bench time (the IMU lost: the measurement must not wait forever)."""

    def __init__(self, max_hold_s: float = 0.05, input_kind: str = "imu"):
        self.max_hold_ns = int(round(max_hold_s * 1e9))
        self.input_kind = input_kind
        self.watermark_ns: int | None = None
        self._heap: list = []
        self._n = 0
        self.held_total = 0
        self.expired = 0

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, item, t_ns: int, kind: str, now_ns: int) -> list:
        heap = self._heap
        if kind == self.input_kind:
            out = []
            while heap and heap[0][0] <= t_ns:
                out.append(heapq.heappop(heap)[3])
            out.append(item)
            if self.watermark_ns is None or t_ns > self.watermark_ns:
                self.watermark_ns = t_ns
            return out
        if self.watermark_ns is not None and t_ns <= self.watermark_ns:
            return [item]  # every held item is later than the watermark: this one goes first
        self._n += 1
        self.held_total += 1
        heapq.heappush(heap, (t_ns, self._n, now_ns, item))
        return self._release_due()

    def _release_due(self) -> list:
        heap = self._heap
        out = []
        wm = self.watermark_ns
        while heap and wm is not None and heap[0][0] <= wm:
            out.append(heapq.heappop(heap)[3])
        return out

    def expire(self, now_ns: int) -> list:
        heap = self._heap
        out = self._release_due()
        while heap and now_ns - heap[0][2] >= self.max_hold_ns:
            out.append(heapq.heappop(heap)[3])
            self.expired += 1
        return out

    def flush(self) -> list:
        heap = self._heap
        return [heapq.heappop(heap)[3] for _ in range(len(heap))]
