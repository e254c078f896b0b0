"""The stepping algorithm: the order in which one communication step calls the slaves (libcosim's ``algorithm``).

- **Gauss-Seidel** (:class:`GaussSeidel`, the default): the components are stepped in system order (panel ->
  controller -> servos); each takes its inputs from the newest outputs, so a controller's command reaches the
  servo in the same step, and the servo's answer reaches the controller in the next.
- **Jacobi** (:class:`Jacobi`): every component takes its inputs from the outputs of the previous communication
  point, then all step (what libcosim's fixed-step algorithm does).

An algorithm is chosen by name once (:func:`algorithm`); the master's Python loop runs its :meth:`Algorithm.stepper`
and the C loop (``loop.c``) the same calls, told which by :attr:`Algorithm.jacobi`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from ..errors import SystemDefinitionError

__all__ = ["ALGORITHMS", "MODES", "Algorithm", "GaussSeidel", "Jacobi", "algorithm"]

#: One slave of the step plan: the slave and its gathers ``(input buffer, numpy.take of the value vector, index)``.
Plan = Sequence[tuple[object, tuple]]


class Algorithm:
    """How one communication step calls the slaves of a plan."""

    #: Its name, as ``--mode`` and ``Master(mode=...)`` give it.
    name: str = ""
    #: The C loop's flag: every input gathered before any slave steps.
    jacobi: bool = False

    def stepper(self, plan: Plan) -> Callable[[float, float], None]:
        """A function that runs one communication step ``(t, h)`` over ``plan``."""
        raise NotImplementedError


class GaussSeidel(Algorithm):
    name, jacobi = "gauss-seidel", False

    def stepper(self, plan: Plan) -> Callable[[float, float], None]:
        def step(t: float, h: float) -> None:
            for s, gathers in plan:
                for buf, take, idx in gathers:
                    take(idx, out=buf)
                s.write_inputs()            # type: ignore[attr-defined]
                s.do_step(t, h)             # type: ignore[attr-defined]
                s.read_outputs()            # type: ignore[attr-defined]
        return step


class Jacobi(Algorithm):
    name, jacobi = "jacobi", True

    def stepper(self, plan: Plan) -> Callable[[float, float], None]:
        def step(t: float, h: float) -> None:
            for _s, gathers in plan:
                for buf, take, idx in gathers:
                    take(idx, out=buf)
            for s, _ in plan:
                s.write_inputs()            # type: ignore[attr-defined]
                s.do_step(t, h)             # type: ignore[attr-defined]
            for s, _ in plan:
                s.read_outputs()            # type: ignore[attr-defined]
        return step


ALGORITHMS: dict[str, Algorithm] = {a.name: a for a in (GaussSeidel(), Jacobi())}
#: The algorithms by name, the default first.
MODES = tuple(ALGORITHMS)


def algorithm(mode: str | Algorithm) -> Algorithm:
    """The algorithm named ``mode`` (or ``mode`` itself); an unknown name is a :class:`SystemDefinitionError`."""
    if isinstance(mode, Algorithm):
        return mode
    found = ALGORITHMS.get(mode) if isinstance(mode, str) else None
    if found is None:
        raise SystemDefinitionError(f"mode = {mode!r}: must be one of {', '.join(MODES)}")
    return found
