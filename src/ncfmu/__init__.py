"""ncfmu: classic NC machine-tool controllers as FMI 2.0 co-simulation FMUs.

The package is layered; importing :mod:`ncfmu` itself imports nothing heavy:

- :mod:`ncfmu.controllers` -- controller logic as plain Python (no FMI);
- :mod:`ncfmu.servo` -- python-control models of a servo axis and its discrete stepper;
- :mod:`ncfmu.fmi` -- the generic pythonfmu adapter, the builder and the modelDescription post-processing;
- :mod:`ncfmu.cosim` -- the co-simulation master on fmpy, the SSP reader/writer, results;
- :mod:`ncfmu.serving` -- a system run in real time behind an OPC UA server (``ncfmu.serve(...)``);
- :mod:`ncfmu.cli` -- the ``ncfmu`` command.
"""

from .version import __version__

__all__ = ["__version__", "serve"]


def serve(*args, **kwargs):
    """Run a system in real time behind an OPC UA server (:func:`ncfmu.serving.serve`; asyncua is imported on
    the call, not with the package)."""
    from .serving import serve as _serve
    return _serve(*args, **kwargs)
