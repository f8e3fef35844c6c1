"""The paper's Figure 2 as one pure node: ``node.VdpsSystem`` takes the bus samples (in time
order, time only from ``sample.t_ns``) through suspension conditioning, the estimator
(``estimation``), the identifier (``identification``) and the predictor with its rollover
warning (``prediction``), and returns its outputs (``outputs``: innovations, estimates, filtered
signals, identification reports, predictions, VDPS_Warning CAN frames). No devices, files,
processes or clocks inside: the applications around it (``app``: file replay, live logging;
``hil``: the bench) feed it and write what it returns."""
