"""NMEA 0183 sentences both ways: generators (``format_*``) and parser (``parse_sentence``,
``NmeaDecoder``), converting at the boundary to the bus field catalogue (SI, paper angles).

Modules, in the order a line goes through them
----------------------------------------------
* :mod:`.sentence` -- the frame of a sentence (``$`` body ``*hh`` CR LF, the XOR checksum), the
  result types (``ParsedSentence``, ``Reject``), the layout tables and the printed precision;
* :mod:`.fields` -- one field both ways: number formatting for the generators, typed getters
  for the parser;
* :mod:`.position` -- GGA, RMC, VTG (position and velocity): generator and parser;
* :mod:`.attitude` -- HDT, THS (heading) and the pitch/roll layouts PASHR, PASHR,HPR, HPR,
  PTNL,AVR: generators and parsers;
* :mod:`.parse` -- ``parse_sentence``: line clean-up, checksum, address -> layout parser, the
  bad input policy;
* :mod:`.decoder` -- ``NmeaDecoder``: lines of one device -> bus samples, with counters.

Conversions (printed value -> catalogue field)
----------------------------------------------
::

    lat_deg   = s_NS (dd + mm.mmmm / 60)          s_NS = +1 for N, -1 for S   (GGA, RMC)
    lon_deg   = s_EW (ddd + mm.mmmm / 60)         s_EW = +1 for E, -1 for W
    speed_mps = v_kn * 1852 / 3600                (or v_kmh / 3.6 when only km/h is printed)
    psi       = wrap(pi/2 - radians(h))           h: heading/course [deg, clockwise from true N]
    theta     = s_p * radians(pitch_printed)      s_p = ATTITUDE_SIGN[layout].pitch_to_paper
    phi       = s_r * radians(roll_printed)       s_r = ATTITUDE_SIGN[layout].roll_to_paper
    sigma_*   = radians(accuracy_printed)         (1-sigma, where the sentence prints it)

Symbols: psi paper yaw [rad, CCW from East], theta paper pitch [rad, nose up positive], phi paper
roll [rad, right side down positive] (``vdps_hil.conventions``); ``gnss_course_rad`` is the course
over ground written as a paper yaw. The generators apply the inverse maps, so a round trip is
exact up to the printed precision (half a unit of the last printed digit).

Layouts (``ParsedSentence.sentence``) and the sample kind they feed
-------------------------------------------------------------------
=============  ==========  =================================================================
GGA            gnss_pos    time, lat, N/S, lon, E/W, quality, sats, HDOP, alt, M, geoid sep, M,
                           diff age, station
RMC            gnss_vel    time, status, lat, N/S, lon, E/W, speed kn, course, date, magvar,
                           E/W[, mode[, nav status]]; speed and course only go on the bus
VTG            gnss_vel    course T, T, course M, M, speed kn, N, speed km/h, K[, mode]
HDT            gnss_att    heading, T
THS            gnss_att    heading, mode (A autonomous, E estimated, M manual, S simulator, V)
PASHR          gnss_att    bare OxTS/Applanix/NovAtel layout: time, heading, T, roll, pitch, heave,
                           roll acc, pitch acc, heading acc, GNSS quality[, INS status]; roll
                           present; sigmas from the accuracies
PASHR,HPR      gnss_att    Ashtech/Spectra: time, heading, pitch, roll, carrier RMS, baseline
                           RMS, ambiguity[, mode, antenna setup, PDOP]
HPR            gnss_att    $GNHPR/$GPHPR (Unicore, ComNav): time, heading, pitch, roll, QF[,
                           sats, age, station]
PTNL,AVR       gnss_att    Trimble: time, yaw, Yaw, tilt, Tilt, roll, Roll, range, quality[,
                           PDOP, sats]; tilt is the pitch-like angle; the labelled slot decides
=============  ==========  =================================================================
"""
