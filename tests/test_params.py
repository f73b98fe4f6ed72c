import pytest

from metaopt import ConfigError, Param
from metaopt.params import resolve

RATE = Param("hmcr", float, 0.9, "memory considering rate", low=0.0, high=1.0)
SIZE = Param("hms", int, 20, "memory size", low=1)
KIND = Param("pitch", str, "bandwidth", "variant", choices=("bandwidth", "resample"))
FLAG = Param("verbose", bool, False, "talk more")


def test_parse_converts_and_validates_each_type():
    assert RATE.parse("0.95", "hs") == 0.95
    assert SIZE.parse("30", "hs") == 30
    assert SIZE.parse("3e1", "hs") == 30
    assert KIND.parse("resample", "hs") == "resample"
    assert FLAG.parse("yes", "hs") is True and FLAG.parse("off", "hs") is False


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("9007199254740993", 2**53 + 1),
        ("9007199254740993.0", 2**53 + 1),
        ("9223372036854775807", 2**63 - 1),
        ("1e3", 1000),
        (" 10.0 ", 10),
        ("1.5e1", 15),
    ],
)
def test_an_int_is_read_exactly_past_a_floats_precision(text, expected):
    """Read through a float, 2**53 + 1 became 2**53; a whole number written as a float is
    still one."""
    assert SIZE.parse(text, "hs") == expected


@pytest.mark.parametrize("text", ["1.0000000000000001", "9007199254740993.5", "1e400", "nan"])
def test_an_int_that_a_float_would_round_or_overflow_is_refused(text):
    with pytest.raises(ConfigError, match=rf"cannot read '{text}'; expected an int in \[1, inf\)"):
        SIZE.parse(text, "hs")


@pytest.mark.parametrize(
    ("param", "text", "expected"),
    [
        (RATE, "1.5", r"'hmcr' = 1.5 is invalid; expected a float in \[0, 1\]"),
        (RATE, "abc", r"cannot read 'abc'; expected a float in \[0, 1\]"),
        (SIZE, "0", r"expected an int in \[1, inf\)"),
        (SIZE, "2.5", "cannot read '2.5'"),
        (KIND, "wobble", "expected one of bandwidth, resample"),
        (FLAG, "maybe", "expected true or false"),
    ],
)
def test_bad_values_name_the_parameter_and_what_is_accepted(param, text, expected):
    with pytest.raises(ConfigError, match=expected):
        param.parse(text, "hs")


def test_open_bounds_exclude_the_endpoint():
    tau = Param("tau", float, 1.0, "time constant", low=0.0, low_open=True)
    assert tau.accepted() == "a float in (0, inf)"
    with pytest.raises(ConfigError):
        tau.validate(0.0, "x")
    assert tau.validate(1e-9, "x") == 1e-9


def test_resolve_fills_defaults_and_suggests_close_names():
    assert resolve((RATE, SIZE), {"hms": 5}, "hs") == {"hmcr": 0.9, "hms": 5}
    with pytest.raises(ConfigError, match="Did you mean 'hmcr'"):
        resolve((RATE, SIZE), {"hmrc": 0.5}, "hs")


@pytest.mark.parametrize("text", ["inf", "-inf", "Infinity", "1e999", "nan"])
def test_a_float_is_finite_unless_the_parameter_takes_infinity(text):
    """inf is no value of an unbounded float (it would reach the optimizer as a step or a
    width); only a parameter declared ``infinite`` (e.g. a friction: no sliding limit) takes
    it, and NaN is never a value."""
    tau = Param("tau", float, 1.0, "time constant", low=0.0, low_open=True)
    with pytest.raises(ConfigError, match=r"expected a float in \(0, inf\)"):
        tau.parse(text, "x")
    free = Param("shift", float, 0.0, "any shift")
    with pytest.raises(ConfigError, match="expected any finite float"):
        free.parse(text, "x")
    friction = Param("friction", float, 0.0, "inf: no limit", low=0.0, infinite=True)
    assert friction.accepted() == "a float in [0, inf]"
    if text in ("inf", "Infinity", "1e999"):
        assert friction.parse(text, "x") == float("inf")
    else:
        with pytest.raises(ConfigError, match=r"expected a float in \[0, inf\]"):
            friction.parse(text, "x")


def test_an_unbounded_side_shows_open():
    assert Param("n", int, 0, "count", low=0).accepted() == "an int in [0, inf)"
    assert Param("n", int, 0, "count", high=5).accepted() == "an int in (-inf, 5]"
    assert Param("r", float, 0.5, "rate", low=0.0, high=1.0).range_text() == "[0, 1]"
