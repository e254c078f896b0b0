"""ncfmu: classic NC machine-tool controllers as FMI 2.0 co-simulation FMUs.

The package is layered; importing :mod:`ncfmu` itself imports nothing heavy:

- :mod:`ncfmu.controllers` -- controller logic as plain Python (no FMI);
- :mod:`ncfmu.servo` -- python-control models of a servo axis and its discrete stepper;
- :mod:`ncfmu.fmi` -- the generic pythonfmu adapter, the builder and the modelDescription post-processing;
- :mod:`ncfmu.cosim` -- the co-simulation master on fmpy, the SSP reader/writer, results;
- :mod:`ncfmu.cli` -- the ``ncfmu`` command.
"""

__version__ = "0.1.0"
