"""Real data (layer 12): readers and writers of the real drives in ``../shared/data/real``, the
pipeline run on what a car actually has, reference comparisons, baselines and the real-car
studies (``tools/real_cars.py``).

Data flow::

    real recording --tools/convert_*.py--> candump / NMEA text / MTi capture --vdps import-->
    MCAP --decode--> Sample stream --(kind_map, gnss-denied windows)--> EstimatorPipeline
    --> Track --(antenna lever arm)--> errors against the reference; baselines on the side

The package holds the parts the converters (``tools/convert_*.py``), the tests and
``tools/real_cars.py`` share, one module per job:

* ``containers``       the arrays a drive reads into: ``ImuSeries``, ``GnssFixes``, ``Reference``
* ``comma2k19``        the comma2k19 RAV4 segment (numpy arrays: u-blox, phone IMU, global pose)
* ``rtklib``           RTKLIB ``.pos``, the rtklibexplorer IMU ``.csv`` with its time-tag file,
                       GPST time scales, the publisher's IMU mounting
* ``capture_writers``  NMEA text and Xsens MTi captures that ``vdps import`` reads
* ``runs``             converted files back into samples through the project's own adapters
                       (``record.importer.build_adapters``: the code path of ``vdps import``),
                       the pipeline run on them, its estimates as a ``Track``
* ``reference``        errors against the reference, dead reckoning, lags
* ``outages``          GNSS-denied windows and the errors at their ends against constant velocity
* ``steering``         the steady-state steering fit (openpilot's learned quantities)

The sensor sets (``configs/sensorsets/*.toml``) are ``vdps_hil.estimation.sensorsets`` (the
replay needs them). Nothing here reads simulator truth.

Frames, signs and symbols (``vdps_hil.conventions``)
-----------------------------------------------------
==============  ======  ===========================================================================
symbol          unit    meaning
==============  ======  ===========================================================================
p, v            m, m/s  CG position / velocity in ENU {g} (EKF states)
l_ant           m       antenna lever arm from the CG, body axes x fwd, y left, z up (model file)
p_ant, v_ant    m, m/s  antenna position / velocity: p + C^T l_ant, v + C^T (w x l_ant)
C               -       C_g^v of eq 1 from the EKF's (phi_g, theta_g, psi_g)
speed           m/s     |v_h| = hypot(v_E, v_N) (horizontal)
course          rad     atan2(v_N, v_E): direction of travel as a paper yaw (CCW from East)
t_s             s       time on the drive's clock (comma2k19: device boot seconds; RTKLIB: GPST
                        seconds since 1970-01-01 without leap seconds, ``gpst_to_unix``)
==============  ======  ===========================================================================
"""
