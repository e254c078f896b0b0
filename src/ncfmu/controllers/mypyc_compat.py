"""``mypyc_attr`` for the runtime modules the builder compiles with mypyc (``fmi/builder.py``'s ``COMPILED``).

mypyc reads ``@mypyc_attr(...)`` at compile time (it resolves the name to ``mypy_extensions.mypyc_attr``); at run
time the decorator does nothing. An FMU runs on the standard library alone, where ``mypy_extensions`` may be
absent: then this no-op stands in for it.

Every class of a compiled module (bar two transient helpers of g7x.py) is ``native_class=False``: its methods are
compiled, its instances keep a ``__dict__``, so ``vars()`` (fmi/state.py's format, ``Controller.check_state``) and
``copy.deepcopy`` (the FMU states) work on them as on the pure-Python classes (bench/README.md has the cost of
that choice). ``allow_interpreted_subclasses=True`` says that a class may be subclassed by code mypyc does not
see (mypyc 2.4.1 still checks a compiled method's ``self`` for exactly the compiled class on an interpreted
class: so the bases that uncompiled controllers subclass, base.py and cycle.py, stay sources).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from mypy_extensions import mypyc_attr
else:
    try:
        from mypy_extensions import mypyc_attr
    except ImportError:                     # an FMU's host without mypy: the decorator is only read by mypyc
        def mypyc_attr(*attrs: str, **kwattrs: object):
            return lambda cls: cls

__all__ = ["mypyc_attr"]
