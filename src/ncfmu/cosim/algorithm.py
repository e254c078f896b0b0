"""The stepping algorithm: the order in which one communication step calls the slaves (libcosim's ``algorithm``).

- **Gauss-Seidel** (:class:`GaussSeidel`, the default): the components are stepped in system order (panel ->
  controller -> servos); each takes its inputs from the newest outputs, so a controller's command reaches the
  servo in the same step, and the servo's answer reaches the controller in the next.
- **Jacobi** (:class:`Jacobi`): every component takes its inputs from the outputs of the previous communication
  point, then all step (what libcosim's fixed-step algorithm does).

An algorithm is chosen by name once (:func:`algorithm`) and says its order once, as data: its
:meth:`~Algorithm.schedule`, the calls of one step as ``(what, slave)`` pairs (:data:`GATHER` its inputs from the
value vectors, :data:`STEP` -- send them and step --, :data:`READ` its outputs). Every loop follows that schedule:
the master's Python loop (:meth:`Algorithm.stepper`), the C loop (``loop.c``, handed the schedule as an array)
and the rest of a step an FMU ended early (:meth:`Algorithm.rest_of_step`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from ..errors import SystemDefinitionError

__all__ = ["ALGORITHMS", "GATHER", "MODES", "READ", "STEP", "Algorithm", "GaussSeidel", "Jacobi", "algorithm"]

#: One slave of the step plan: the slave and its gathers ``(input buffer, numpy.take of the value vector, index)``.
Plan = Sequence[tuple[object, tuple]]
#: What a call of the schedule does to its slave (loop.c's PLAN_GATHER, PLAN_STEP, PLAN_READ are these numbers).
GATHER, STEP, READ = 0, 1, 2
#: One step's calls in order: ``(what, index of the slave in the plan)``.
Schedule = tuple[tuple[int, int], ...]


class Algorithm:
    """How one communication step calls the slaves of a plan: its :meth:`schedule`, the one statement of it."""

    #: Its name, as ``--mode`` and ``Master(mode=...)`` give it.
    name: str = ""

    def schedule(self, n: int) -> Schedule:
        """The calls of one communication step over ``n`` slaves (in system order)."""
        raise NotImplementedError

    def stepper(self, plan: Plan) -> Callable[[float, float], None]:
        """A function that runs one communication step ``(t, h)`` over ``plan``."""
        return _runner(plan, self.schedule(len(plan)))

    def rest_of_step(self, plan: Plan, k: int) -> Callable[[float, float], None]:
        """The calls of a step that follow the step of slave ``k`` (it ended the run having made its step whole)."""
        schedule = self.schedule(len(plan))
        return _runner(plan, schedule[schedule.index((STEP, k)) + 1:])


def _runner(plan: Plan, schedule: Schedule) -> Callable[[float, float], None]:
    calls = [(what, plan[k][0], plan[k][1]) for what, k in schedule]

    def step(t: float, h: float) -> None:
        for what, s, gathers in calls:
            if what == GATHER:
                for buf, take, idx in gathers:
                    take(idx, out=buf)
            elif what == STEP:
                s.write_inputs()            # type: ignore[attr-defined]
                s.do_step(t, h)             # type: ignore[attr-defined]
            else:
                s.read_outputs()            # type: ignore[attr-defined]
    return step


class GaussSeidel(Algorithm):
    name = "gauss-seidel"

    def schedule(self, n: int) -> Schedule:
        return tuple((what, k) for k in range(n) for what in (GATHER, STEP, READ))


class Jacobi(Algorithm):
    name = "jacobi"

    def schedule(self, n: int) -> Schedule:
        return tuple((what, k) for what in (GATHER, STEP, READ) for k in range(n))


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
