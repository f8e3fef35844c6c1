"""Wire formats both ways: CAN (DBC via cantools), NMEA 0183, IMU binary.

Bytes in, bus samples (``bus.samples``: catalogue fields in SI, paper angles) out, and back for
the simulator and the bench. The DBCs: ``dbc_cache`` parses a DBC once with cantools and
caches what the decoders need as JSON, ``dbc_compile`` compiles a message layout to shifts and
masks (tested equal to cantools). The vdps chassis bus (``dbc/vdps.dbc``): ``can_dbc`` is the
DBC as the codec sees it (IDs, kinds, value/counter/CRC signals, ranges), ``can_e2e`` the
rolling-counter and CRC-8/SAE-J1850 rules, ``can_encode`` the quantisation and the encoders,
``can_decode`` the counting decoder, ``can_busload`` frame lengths and the bus load (a car's own
DBC is applied by ``adapters.signalmap_decoder``). The serial devices: ``framing`` cuts a byte
stream into lines and gives each message its receive time; ``nmea/`` the GNSS sentences (GGA,
RMC, VTG position and velocity; HDT, THS heading; PASHR, PASHR,HPR, HPR, PTNL,AVR attitude),
parsed into samples and generated; ``imu_mtdata2`` one Xsens MTi ``MTData2`` message (encode,
decode) and ``imu_decoder`` the MTi byte stream (Xbus framing, receive times, samples).
"""
