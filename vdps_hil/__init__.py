"""vdps-hil: the vehicle dynamics prediction system of Hsu & Chen (Sensors 2012, 12, 15778)
as a CAN/NMEA logger, estimator pipeline, truth simulator, model workbench and HIL bench.

Data flow (the package tree follows it)::

    adapters/ --(bus samples)--> estimation/ --> identification/ --> prediction/ --> CAN warning
        ^                             ^
    codecs/ (wire formats)        model/ (frames, params, physics core, effects)
        ^                             v
    sim/ (truth simulator + sensor models) ; record/ (MCAP) ; workbench/ ; hil/ ; cli/
"""

__version__ = "0.1.0"

from vdps_hil import deferred_imports as _deferred_imports

_deferred_imports.install()  # python-can's MF4 backend (asammdf, pandas) loads when an MF4 is opened
