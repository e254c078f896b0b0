"""The part check, the report and the thread judge read the configured sequencer's meaning
(ncfmu.controllers.meaning), not the program: a program reads the same for them as for the controller."""

from ncfmu.controllers.sequencer import CutSequencer
from ncfmu.systems.part import LathePart
from ncfmu.systems.report import LatheCycle

THREAD = "G97 S600 M03\nG00 X32. Z5.\nG 92 X29.2 Z-20. F1.5\nX28.4\nG00 X40.\nM30\n"


def test_how_a_program_writes_x_is_read_from_its_words_not_its_comments():
    """A G8 inside a ';' comment is no word: the program writes X as a diameter only (the report said "diameter
    and radius" when it re-read the program with its own pattern, which knew only the '( )' comments)."""
    text = "G7 G21\nG00 X20. Z0 ; a radius would be G8\nG01 Z-5. F100\nM30\n"
    assert CutSequencer(program=text).meaning.x_written == "diameter"
    assert LatheCycle("seq", "x", "z").x_written({"seq": {"program": text}}) == "diameter"
    assert LatheCycle("seq", "x", "z").x_written({"seq": {}}) is None          # the registers: radii, said so


def test_a_thread_written_with_a_space_in_its_g_word_is_judged():
    """'G 92' is G92 (a letter and its number may stand apart): the sequencer cuts the thread, so the part check
    judges it -- two passes, the text's line 3 (the judge skipped any program whose text did not hold 'G92')."""
    part = LathePart("seq", "x_axis", "z_axis", spindle="spindle")
    judge = part.threads({"seq": {"program": THREAD, "x_start": 20.0, "z_start": 5.0}})
    assert judge is not None
    assert [(p.line, p.lead) for p in judge.plan] == [(3, 1.5), (4, 1.5)]
