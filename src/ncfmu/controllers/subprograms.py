"""Fanuc 0i-T subprograms: ``M98 P`` calls, ``M99`` returns, expanded into the blocks a CNC runs, in order.

The subprograms are further ``O`` programs in the program's text after the main program's M02/M30, each ending
with M99, as a CNC holds them in its memory (:func:`.gcode.read` with a dialect's ``subprograms``).

``M98 P<repeats><program>``: P's last four digits name the program O<program>, the digits before them how many
times it runs (``M98 P30100``: O0100 three times; ``M98 P100``: once); or ``M98 P<program> L<repeats>``. The
other words of the M98 block run first (Fanuc), then the subprogram. ``M99`` returns to the block after the
call; in the main program ``M99 P<n>`` jumps to the block N<n> (forward: a jump back would repeat the program
endlessly). Calls nest up to :data:`MAX_NESTING` levels (the main program calling O1 is one level).

A block keeps its own text line (:attr:`.gcode.Block.line`): errors and ``seq.line`` name the line in the text,
also for a subprogram's blocks however often they run.
"""

from __future__ import annotations

from dataclasses import replace

from ..errors import ProgramError, ProgramErrors
from .gcode import Block

#: Calls nest at most this deep (Fanuc 0i-T: four levels).
MAX_NESTING = 4
#: More blocks than this, run in order with every call expanded, are refused (a program runs a few thousand).
MAX_RUN_BLOCKS = 100_000


def _codes(b: Block) -> set[int]:
    return {code for code, _ in b.m}


def _without(b: Block, letters: str) -> Block:
    """The block without the words ``letters`` (M98's P and L, M99's P: they are the call's, not a move's)."""
    return replace(b, values={k: v for k, v in b.values.items() if k not in letters})


def _split(blocks: list[Block]) -> tuple[list[Block], dict[int, list[Block]], list[ProgramError]]:
    """The main program (up to its M02/M30) and the subprograms by number, with the errors in naming them."""
    end = next((k for k, b in enumerate(blocks) if b.ends), len(blocks) - 1)
    main = blocks[:end + 1]
    subs: dict[int, list[Block]] = {}
    errors: list[ProgramError] = []
    current: list[Block] | None = None
    for b in blocks[end + 1:]:
        if "O" in b.values and (current is None or any(99 in _codes(x) for x in current)):
            o = b.values["O"]
            if o != int(o) or not 1 <= o <= 9999:
                errors.append(b.err(b.col("O"), f"O{o:g}: a program number is a whole number 1..9999"))
                current = []
                continue
            if int(o) in subs:
                first = subs[int(o)][0].line if subs[int(o)] else 0
                errors.append(b.err(b.col("O"), f"O{int(o):04d} again: line {first} is O{int(o):04d}"))
                current = []
                continue
            current = subs[int(o)] = [b]
        elif current is not None:
            current.append(b)
    return main, subs, errors


def _call(b: Block, subs: dict[int, list[Block]]) -> tuple[int, int]:
    """The program number and the repeat count of an M98 block."""
    v = b.values
    if "P" not in v:
        raise b.err(b.col("M"), "M98 names the subprogram: M98 P<repeats><program> (P30100: O0100 three times)")
    p = v["P"]
    if p != int(p) or p < 1 or p > 99_999_999:
        raise b.err(b.col("P"), f"P{p:g}: M98's P is a whole number of at most 8 digits: the repeats (up to 4) and "
                                "the program number (4)")
    times, number = divmod(int(p), 10000)
    if "L" in v:
        if times:
            raise b.err(b.col("L"), f"P{p:g} with L: give the repeats in P's first four digits or in L, not both")
        lv = v["L"]
        if lv != int(lv) or not 1 <= lv <= 9999:
            raise b.err(b.col("L"), f"L{lv:g}: the repeat count is a whole number 1..9999")
        times = int(lv)
    times = times or 1
    if number not in subs:
        held = ", ".join(f"O{k:04d}" for k in sorted(subs)) or "none"
        raise b.err(b.col("P"), f"P{p:g}: M98 calls O{number:04d}, which the program does not hold (its "
                                f"subprograms after M02/M30: {held})")
    return number, times


def _check(b: Block, subs: dict[int, list[Block]], main: bool) -> None:
    """The words of the calls and returns of one block."""
    codes = _codes(b)
    if 98 in codes and 99 in codes:
        raise b.err(b.col("M"), "M98 and M99 in one block: give each a block of its own")
    if "L" in b.values and 98 not in codes:
        raise b.err(b.col("L"), "L (a repeat count) belongs to M98")
    if 98 in codes:
        if any(g in (70, 71, 4) for g, _ in b.g):
            raise b.err(b.col("M"), "M98 in a G04/G70/G71 block: P is theirs there, give M98 a block of its own")
        _call(b, subs)
    if 99 in codes:
        if b.ends:
            raise b.err(b.col("M"), "M99 with M02/M30: the program ends either way")
        if "P" in b.values and not main:
            raise b.err(b.col("P"), "M99 P in a subprogram (return to N<P> of the caller) is not in the subset: "
                                    "M99 returns to the block after the call")
        if main and "P" not in b.values:
            raise b.err(b.col("M"), "M99 in the main program starts it again endlessly: give M99 P<n> (jump to "
                                    "N<n>) or end with M30")


def run_order(blocks: list[Block]) -> list[Block]:
    """The blocks of a program (main and subprograms, :func:`.gcode.read`'s) in the order the CNC runs them.

    Raises
    ------
    ProgramError
        naming the line: a call to a program the text does not hold, calls nested deeper than
        :data:`MAX_NESTING`, M99 P to a block not after it; every error of the calls' words at once.
    """
    main, subs, errors = _split(blocks)
    for b in main:
        try:
            _check(b, subs, True)
        except ProgramError as err:
            errors.append(err)
    for program in subs.values():
        for b in program:
            try:
                _check(b, subs, False)
            except ProgramError as err:
                errors.append(err)
    if len(errors) == 1:
        raise errors[0]
    if errors:
        raise ProgramErrors(sorted(errors, key=lambda e: e.line_no))
    if not subs and not any(_codes(b) & {98, 99} for b in main):
        return blocks
    out: list[Block] = []

    def run(program: list[Block], depth: int) -> None:
        numbers = {b.n: k for k, b in enumerate(program) if b.n is not None}
        k = 0
        while k < len(program):
            b = program[k]
            k += 1
            codes = _codes(b)
            if len(out) >= MAX_RUN_BLOCKS:
                raise b.err(1, f"more than {MAX_RUN_BLOCKS} blocks run with the subprograms' calls expanded")
            if 98 in codes:
                number, times = _call(b, subs)
                if depth + 1 > MAX_NESTING:
                    raise b.err(b.col("M"), f"M98 P{b.values['P']:g}: subprogram calls nested {depth + 1} deep, "
                                            f"at most {MAX_NESTING} (O{number:04d} would run at level {depth + 1})")
                out.append(_without(b, "PL"))
                for _ in range(times):
                    run(subs[number], depth + 1)
            elif 99 in codes:
                out.append(_without(b, "P"))
                if depth:
                    return
                target = int(b.values["P"])
                if target not in numbers:
                    raise b.err(b.col("P"), f"M99 P{target}: N{target} is not in the main program")
                if numbers[target] < k:
                    raise b.err(b.col("P"), f"M99 P{target}: N{target} stands before the M99 (line "
                                            f"{program[numbers[target]].line}): the program would repeat endlessly")
                k = numbers[target]
            else:
                out.append(b)

    run(main, 0)
    return out


__all__ = ["MAX_NESTING", "MAX_RUN_BLOCKS", "run_order"]
