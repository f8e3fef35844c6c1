"""``/gnss/fix`` from the NMEA bytes of a serial stream, for writers that only see the bytes (the
simulator's recording sink): each GGA position decoded by the project's codecs (``LineFramer``,
``NmeaDecoder``, the same a live logger uses) becomes a ``foxglove.LocationFix`` through
``RecordingWriter.write_location_fix``. Sentences that do not decode are skipped (the raw bytes
stay on ``/raw/serial/<device>``, the truth of the recording)."""

from __future__ import annotations

from vdps_hil.codecs.framing import LineFramer
from vdps_hil.codecs.nmea.decoder import NmeaDecoder

__all__ = ["GnssFixTap"]


class GnssFixTap:
    """``feed(t_ns, chunk)``: the chunk's complete NMEA lines decoded; every ``gnss_pos`` sample
    written to ``writer`` as ``/gnss/fix`` (time: the line's receive time by the framer's rule).
    ``fixes`` counts what was written."""

    def __init__(self, writer, device: str, baud: int):
        self.writer = writer
        self.framer = LineFramer(baud)
        self.decoder = NmeaDecoder(device)
        self.fixes = 0

    def feed(self, t_ns: int, chunk: bytes) -> None:
        for t_line, line in self.framer.feed(t_ns, chunk):
            for s in self.decoder.feed_line(t_line, line):
                if s.kind == "gnss_pos" and self.writer.write_location_fix(s):
                    self.fixes += 1
