"""The master algorithm against fake slaves: call order, Gauss-Seidel vs Jacobi, connection checks."""

import numpy as np
import pytest
from fakes import FakeSlave, chain
from hypothesis import given, settings
from hypothesis import strategies as st

from ncfmu.cosim.master import Master
from ncfmu.cosim.ssp import Component, Connection, System
from ncfmu.errors import SystemDefinitionError


def test_gauss_seidel_passes_new_outputs_within_the_step():
    m, log = chain("gauss-seidel")
    r = m.run()
    # step 1: a = 0 + 1 = 1, b = 1 + 10 = 11; step 2: a = 12, b = 22; step 3: a = 23, b = 33
    assert list(r["a.y"]) == [0, 1, 12, 23] and list(r["b.y"]) == [0, 11, 22, 33]
    assert log == ["a", "b"] * 3


def test_jacobi_uses_the_previous_communication_point():
    m, _ = chain("jacobi")
    r = m.run()
    # step 1: a = 0+1, b = 0+10; step 2: a = 10+1, b = 1+10; step 3: a = 11+1, b = 11+10
    assert list(r["a.y"]) == [0, 1, 11, 12] and list(r["b.y"]) == [0, 10, 11, 21]


def test_the_algorithm_is_chosen_once_by_name():
    """Gauss-Seidel vs Jacobi is decided in one place (cosim/algorithm.py): by name, or an Algorithm given; an
    unknown name is refused naming the choices; the loops follow the algorithm's own schedule (test_algorithm.py)."""
    from ncfmu.cosim.algorithm import ALGORITHMS, MODES, GaussSeidel, Jacobi, algorithm
    assert MODES == ("gauss-seidel", "jacobi") and [type(a) for a in ALGORITHMS.values()] == [GaussSeidel, Jacobi]
    m, _ = chain("jacobi")
    assert m.algorithm is ALGORITHMS["jacobi"] and m.mode == "jacobi"
    assert isinstance(algorithm(GaussSeidel()), GaussSeidel) and isinstance(algorithm(Jacobi()), Jacobi)
    with pytest.raises(SystemDefinitionError, match="mode = 'gauss': must be one of gauss-seidel, jacobi"):
        chain("gauss")


@pytest.mark.parametrize("conn, message", [
    (Connection("a", "y", "c", "u"), "no component 'c'"),
    (Connection("a", "nope", "b", "u"), "a has no variable 'nope'"),
    (Connection("a", "u", "b", "u"), "is an input, not an output"),
    (Connection("a", "y", "b", "k"), "is a parameter, not an input"),
])
def test_bad_connections_named_before_running(conn, message):
    log = []
    system = System("bad", [Component("a", "Fake"), Component("b", "Fake")], [conn], stop_time=1.0)
    with pytest.raises(SystemDefinitionError, match=message):
        Master(system, [FakeSlave("a", log), FakeSlave("b", log)])


def test_unknown_start_value_is_named():
    m, _ = chain("gauss-seidel")
    with pytest.raises(SystemDefinitionError, match="unknown instance 'zz'"):
        m.run(start_values={"zz.k": 1.0})


@settings(max_examples=50, deadline=None)
@given(reals=st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=20),
       seed=st.integers(0, 2 ** 31 - 1))
def test_result_csv_is_byte_for_byte_fmpys(tmp_path_factory, reals, seed):
    """Result.to_csv writes exactly what fmpy's write_csv writes (Booleans as 0/1), and read_csv reads it back."""
    from fmpy.util import read_csv, write_csv

    from ncfmu.cosim.result import Result
    rng = np.random.default_rng(seed)
    n = len(reals)
    data = np.empty(n, dtype=[("time", np.float64), ("a.x", np.float64), ("a.n", np.int32), ("a.on", np.bool_)])
    data["time"], data["a.x"] = np.arange(n) * 1e-3, reals
    data["a.n"], data["a.on"] = rng.integers(-2 ** 31, 2 ** 31 - 1, n), rng.integers(0, 2, n).astype(bool)
    folder = tmp_path_factory.mktemp("csv")
    ours = Result(data).to_csv(folder / "ours.csv")
    as_ints = data.astype([(k, np.int32 if data.dtype[k] == np.bool_ else data.dtype[k]) for k in data.dtype.names])
    write_csv(str(folder / "fmpy.csv"), as_ints)
    assert ours.read_bytes() == (folder / "fmpy.csv").read_bytes()
    back = read_csv(str(ours))
    assert np.array_equal(back["a.x"], data["a.x"]) and np.array_equal(back["a.n"], data["a.n"])
    assert np.array_equal(back["a.on"].astype(bool), data["a.on"])


@pytest.mark.parametrize("fmi_type, raw, value", [("Real", "1e-3", 1e-3), ("Integer", "-3", -3), ("Boolean", "1", True),
                                                  ("Boolean", "false", False), ("String", "M0: END", "M0: END")])
def test_fmi_text_is_parsed_by_its_type(fmi_type, raw, value):
    from ncfmu.ports import parse_text
    assert parse_text(fmi_type, raw) == value and type(parse_text(fmi_type, raw)) is type(value)


@pytest.mark.parametrize("fmi_type, raw", [("Boolean", "yes"), ("Boolean", "True"), ("Integer", "2.5"),
                                           ("Real", "abc")])
def test_fmi_text_of_the_wrong_type_is_refused_not_guessed(fmi_type, raw):
    from ncfmu.ports import parse_text
    with pytest.raises(ValueError):
        parse_text(fmi_type, raw)
