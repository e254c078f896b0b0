"""Co-simulation: the master algorithm (:mod:`.master`), the fmpy slave (:mod:`.fmu`, the only module
that talks to ``fmpy.fmi2``), the SSP reader/writer (:mod:`.ssp`) and results (:mod:`.result`)."""
