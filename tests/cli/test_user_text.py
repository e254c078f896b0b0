"""Text from the user -- a --set value, a numeric option, an .ssv file, an input or result CSV -- is read by one
parser of numbers (ASCII decimal only: Python's float() and numpy also take any Unicode digit, '_' and Unicode
spaces) and handed to an FMU only as UTF-8 without NUL. A value that breaks the rule is one line naming the
variable, the value and the rule, exit status 2 -- never a traceback, never a number it was not."""

from __future__ import annotations

import math
import subprocess
import zipfile

import pytest
from conftest import ROOT
from hypothesis import given
from hypothesis import strategies as st
from test_cli_errors import NCFMU, ncfmu, refused

from ncfmu.cosim.result import Result
from ncfmu.errors import ConfigError, SystemDefinitionError
from ncfmu.ports import NUMBER_RULE, Port, parse_integer, parse_real

NOT_ASCII_DECIMAL = ["\u0665", "\uff11", "1_0", "\u0661.5", "5\u00a0", "\U0001d7d3"]
FEED = ["run", "grinder_feed", "--stop-time", "0.01"]


# -- the one parser ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("text", NOT_ASCII_DECIMAL)
def test_numbers_python_would_take_are_not_ascii_decimal(text):
    float(text)                                   # Python takes each of them ...
    with pytest.raises(ValueError, match=r"must be a number in ASCII decimal"):
        parse_real(text)                          # ... ncfmu does not
    with pytest.raises(ConfigError, match=r"must be a number in ASCII decimal"):
        Port("start_at", "parameter", "Real", 0.1).check(text)


@given(st.text(max_size=12))
def test_parse_real_takes_exactly_the_ascii_decimals_and_reads_them_as_float(text):
    try:
        value = parse_real(text)
    except ValueError:
        return
    assert text.isascii() and "_" not in text
    assert value == float(text) or (math.isnan(value) and math.isnan(float(text)))


@given(st.one_of(st.integers(), st.floats(allow_nan=False)))
def test_every_number_python_writes_reads_back(x):
    assert parse_real(repr(float(x))) == float(x)
    if isinstance(x, int):
        assert parse_integer(str(x)) == x


@pytest.mark.parametrize("text", ["+3", "-0", " 12 ", "007"])
def test_whole_numbers_in_ascii_digits(text):
    assert parse_integer(text) == int(text)
    for bad in ("\u0662", "1_000", "1.0", "0x10"):
        with pytest.raises(ValueError, match="ASCII digits"):
            parse_integer(bad)


# -- the command line -------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("text", NOT_ASCII_DECIMAL[:3])
def test_set_of_a_number_not_in_ascii_decimal_is_refused_naming_it(project, tmp_path, text):
    """``--set panel.start_at=٥`` ran as 5."""
    proc = ncfmu(*FEED, "--out", str(tmp_path), "--set", f"panel.start_at={text}")
    refused(proc, "run", f"panel.start_at = {text!r}: {NUMBER_RULE}")


@pytest.mark.parametrize("option", ["--stop-time", "--step", "--output-interval"])
def test_numeric_options_take_ascii_decimal_only(tmp_path, option):
    refused(ncfmu(*FEED, "--out", str(tmp_path), option, "\u0665"), "run",
            f"argument {option}: '\u0665': {NUMBER_RULE}")


def test_a_whole_number_option_takes_ascii_digits_only(tmp_path):
    refused(ncfmu("sweep", "lathe_taper", "--vary", "seq.block[1].Xd=0.4", "--workers", "\u0662", "--out",
                  str(tmp_path)), "sweep", "argument --workers: '\u0662': must be a whole number in ASCII digits")


@pytest.mark.slow
def test_a_string_that_is_not_utf8_is_one_line_naming_the_variable(project, tmp_path):
    """``--set "feed.program=$(printf 'M0: X+D3F7\\xff')"`` was a UnicodeEncodeError traceback (cosim/fmu.py)."""
    proc = subprocess.run([NCFMU, *FEED, "--out", str(tmp_path), "--set", b"feed.program=M0: X+D3F7\xff"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    refused(proc, "run", "feed.program = 'M0: X+D3F7\\udcff'",
            "must be UTF-8 text (the byte 0xff at position 10 is not)")


def test_a_string_with_nul_is_refused_not_cut_short():
    from ncfmu.cosim.fmu import typed_value
    with pytest.raises(ConfigError, match=r"feed.program = 'M0: END\\x00M1: END': must be text without NUL"):
        typed_value("feed.program", "String", "M0: END\x00M1: END")
    assert typed_value("feed.program", "String", "M0: X+D3F7 \u00e9") == "M0: X+D3F7 \u00e9"   # UTF-8 is fine


# -- files: an input CSV, an .ssv, a result CSV -----------------------------------------------------------
@pytest.mark.slow
def test_an_input_csv_number_not_in_ascii_decimal_is_refused(project, tmp_path):
    table = tmp_path / "in.csv"
    table.write_text("time,feed.feed_override\n0,1\n0.005,\u0660.5\n", encoding="utf-8")
    proc = ncfmu(*FEED, "--out", str(tmp_path), "--input", str(table))
    refused(proc, "run", f"{table}: line 3: feed.feed_override = '\u0660.5': not a number", NUMBER_RULE)


@pytest.mark.slow
def test_an_ssv_number_not_in_ascii_decimal_is_refused(project, tmp_path):
    src = zipfile.ZipFile(ROOT / "ssp" / "grinder_feed.ssp")
    edited = tmp_path / "grinder_feed.ssp"
    with zipfile.ZipFile(edited, "w") as out:
        for n in src.namelist():
            data = src.read(n)
            if n == "resources/feed.ssv":
                assert b'<ssv:Real value="4.0" />' in data
                data = data.replace(b'<ssv:Real value="4.0" />', '<ssv:Real value="\u0664.0" />'.encode())
            out.writestr(n, data)
    proc = ncfmu("run", str(edited), "--stop-time", "0.01", "--out", str(tmp_path / "o"))
    refused(proc, "run", "parameter D3", "'\u0664.0' is not a valid Real", NUMBER_RULE)


def test_a_result_csv_number_not_in_ascii_decimal_is_refused(tmp_path):
    table = tmp_path / "run.csv"
    table.write_text("time,x\n0,1\n0.1,\u0662\n", encoding="utf-8")
    with pytest.raises(SystemDefinitionError, match=r"line 3: x = '\u0662': not a number or True/False \(must be"):
        Result.from_csv(table)
    table.write_text("time,x\n0,1\n0.1,1_0\n", encoding="utf-8")
    with pytest.raises(SystemDefinitionError, match=r"line 3: x = '1_0': not a number or True/False"):
        Result.from_csv(table)
    table.write_text("time,x\n0,1\n0.1,-2.5e-3\n", encoding="utf-8")
    assert list(Result.from_csv(table).data["x"]) == [1.0, -2.5e-3]


def test_an_ssd_unit_definition_is_read_in_ascii_decimal():
    """An .ssd's ssd:Unit attributes are text too: the exponents and the factor by the same parser."""
    from ncfmu.cosim.units import Unit
    assert Unit.of("mm", {"m": "1"}, "0.001") == Unit("mm", (0, 1, 0, 0, 0, 0, 0, 0), 0.001, 0.0)
    for exponents, factor in (({"m": "\u0661"}, "0.001"), ({"m": "1"}, "\u0660.001"), ({"m": "1"}, "1_0")):
        with pytest.raises(SystemDefinitionError, match="unit 'mm': BaseUnit exponents must be whole numbers"):
            Unit.of("mm", exponents, factor)
