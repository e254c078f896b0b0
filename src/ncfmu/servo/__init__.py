"""Servo axis: python-control models (:mod:`.model`) and the stepper inside the FMU (:mod:`.axis`)."""
