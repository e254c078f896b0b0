"""ncfmu's version, in a module of its own below every layer: the package root (``ncfmu.__version__``), the builder
and the server read it from here, and the root imports nothing of theirs."""

__version__ = "0.1.0"
