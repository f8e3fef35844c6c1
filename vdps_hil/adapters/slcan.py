"""slcan (Lawicel) serial CAN adapters: python-can's slcan bus reading in chunks, the receive
lines of a byte stream parsed into frames (for the reader process of ``CanAdapter``), and the
line of a frame (what an adapter sends, for emulators and tests).
"""

from __future__ import annotations

import os

__all__ = ["SlcanLines", "fast_slcan_class", "slcan_line", "lock_port"]


def fast_slcan_class():
    """python-can's slcan bus, reading what is waiting instead of one byte per call.

    python-can's ``slcanBus._read`` calls ``serial.read(1)`` once per byte (about 22 calls per
    frame), which tops out near 13,000 frames/s on its own and far lower next to a recorder.
    This subclass keeps the protocol, the options and every other method of python-can's class
    and only replaces the byte reading: it reads ``in_waiting`` bytes at once, splits at CR
    (frame/OK) and BEL (error), and never raises on bytes that are not ASCII (they are replaced,
    and the malformed line is rejected by the frame parser and counted by the adapter).
    """
    import serial
    from can.exceptions import error_check
    from can.interfaces.slcan import slcanBus

    class FastSlcanBus(slcanBus):
        def _read(self, timeout):
            buf = self._buffer
            deadline = serial.Timeout(timeout)
            with error_check("Could not read from serial device"):
                while True:
                    i = buf.find(b"\r")
                    k = buf.find(b"\x07", 0, i if i >= 0 else len(buf))
                    if k >= 0:
                        i = k
                    if i >= 0:
                        line = bytes(buf[:i + 1]).decode("ascii", "replace")
                        del buf[:i + 1]
                        return line
                    port = self.serialPortOrig
                    n = port.in_waiting
                    data = port.read(n if n else 1)
                    if data:
                        buf.extend(data)
                        if len(buf) > 65536:  # garbage without terminators: drop it
                            del buf[:-64]
                        continue
                    if deadline.expired():
                        return None

    return FastSlcanBus


class SlcanLines:
    """slcan (Lawicel) receive lines -> ``can.Message``, for bytes a reader process read.

    Lines end at CR; BEL (0x07) is the adapter's error reply (counted ``slcan_errors``); a CR
    alone is the reply to a command. Frames: ``t``/``T`` (11/29-bit data), ``r``/``R`` (remote),
    ``d``/``D`` and ``b``/``B`` (CAN FD, ``b``/``B`` with bit-rate switch), ID in hex, DLC
    digit (hex for FD), data hex -- python-can's slcan receive format. A line that does not
    parse is counted ``bad_frames`` (the first kept in ``last_error``); a partial line waits
    for the next chunk (at most 4 KiB of it).
    """

    FD_LEN = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)

    def __init__(self, health):
        import can

        self._message = can.Message
        self.health = health
        self._rest = b""

    def reset(self) -> None:
        self._rest = b""

    def feed(self, t_ns: int, data: bytes, timestamp: float) -> list:
        buf = self._rest + data if self._rest else data
        if b"\x07" in buf:
            n = buf.count(b"\x07")
            self.health.count("slcan_errors", n)
            buf = buf.replace(b"\x07", b"\r")
        lines = buf.split(b"\r")
        rest = lines.pop()
        self._rest = rest if len(rest) <= 4096 else b""
        out = []
        msg = self._message
        for ln in lines:
            if not ln:
                continue
            c = ln[0]
            if c in (122, 90):  # z, Z: the adapter acknowledges a frame we sent
                continue
            try:
                if c == 116:  # t
                    dlc = ln[4] - 48
                    m = msg(timestamp=timestamp, arbitration_id=int(ln[1:4], 16),
                            is_extended_id=False, dlc=dlc, data=bytes.fromhex(ln[5:5 + 2 * dlc].decode()),
                            check=False)
                    if not 0 <= dlc <= 8 or len(m.data) != dlc:
                        raise ValueError("DLC does not match the data")
                else:
                    m = self._other(ln, timestamp)
            except (ValueError, IndexError, UnicodeDecodeError) as e:
                self._bad(ln, e)
                continue
            out.append((t_ns, m))
        return out

    def _other(self, ln: bytes, timestamp: float):
        kind = chr(ln[0])
        if kind not in "TrRdDbB":
            raise ValueError(f"not an slcan frame ({kind!r})")
        ext = kind in "TRDB"
        n_id = 8 if ext else 3
        aid = int(ln[1:1 + n_id], 16)
        code = int(chr(ln[1 + n_id]), 16)
        fd = kind in "dDbB"
        dlc = self.FD_LEN[code] if fd else code
        if not fd and dlc > 8:
            raise ValueError(f"DLC {dlc} > 8")
        remote = kind in "rR"
        data = b"" if remote else bytes.fromhex(ln[2 + n_id:2 + n_id + 2 * dlc].decode())
        if not remote and len(data) != dlc:
            raise ValueError("DLC does not match the data")
        return self._message(timestamp=timestamp, arbitration_id=aid, is_extended_id=ext,
                             is_remote_frame=remote, is_fd=fd, bitrate_switch=kind in "bB",
                             dlc=dlc, data=data, check=False)

    def _bad(self, ln: bytes, e: BaseException) -> None:
        h = self.health
        h.count("bad_frames")
        if h.counters.get("bad_frames") == 1:
            h.last_error = f"bad slcan line {ln[:40]!r}: {e}"[:200]


def slcan_line(arbitration_id: int, data: bytes, is_extended_id: bool = False) -> bytes:
    """The slcan (Lawicel) ASCII line of a classic data frame: ``t`` + 3 hex ID (``T`` + 8 for
    29-bit) + DLC digit + data hex + CR. What an slcan adapter sends for a received frame."""
    if is_extended_id:
        return b"T%08X%d%s\r" % (arbitration_id, len(data), data.hex().upper().encode())
    return b"t%03X%d%s\r" % (arbitration_id, len(data), data.hex().upper().encode())


def lock_port(channel: str) -> int | None:
    """Take the advisory exclusive lock of an slcan adapter's serial device path (``channel``,
    ``PATH[@BAUD]``) before python-can opens it, which it does without one: a descriptor holding
    ``flock(LOCK_EX)`` for the bus's life (close it after the bus). Returns None for a URL or a
    path that does not exist (python-can reports those). Raises OSError when another exclusive
    reader holds the device (``SerialAdapter`` opens ports so): python-can's set-up would write
    commands to it and read its bytes. Seen in CI: a bench's pipeline child reconnecting its
    slcan bus by path to a pseudo-terminal number the kernel had since given to another test's
    IMU, whose bytes it then consumed (8,460 of 56,447 reached that test)."""
    import fcntl

    path = str(channel).split("@", 1)[0]
    if "://" in path or not os.path.exists(path):
        return None
    fd = os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise OSError(f"{path} is in use by another reader (locked)") from None
    return fd
