"""The shared validation helpers and the record loader: messages name the field."""

import math
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
import pytest

from ethical_planner.records import errors_in, from_mapping, read_toml, to_plain
from ethical_planner.validation import (
    check_finite,
    check_non_negative,
    check_numeric_fields_finite,
    check_positive,
    finite_array,
    non_negative_array,
    parse_enum,
    positive_array,
    shaped_array,
    vector_array,
)


class Colour(StrEnum):
    RED = "red"
    GREEN = "green"


def test_scalar_checks_name_owner_and_field():
    check_finite("car", speed=3.0, lane=None)
    with pytest.raises(ValueError, match=r"^car.speed must be a finite number, got nan$"):
        check_finite("car", speed=math.nan)
    with pytest.raises(ValueError, match=r"^car.speed must be a finite number, got 'fast'$"):
        check_finite("car", speed="fast")
    with pytest.raises(ValueError, match=r"^car.flag must be a finite number, got True$"):
        check_finite("car", flag=True)
    with pytest.raises(ValueError, match=r"^car.length must be > 0, got 0.0$"):
        check_positive("car", width=1.0, length=0.0)
    check_non_negative("car", gap=0.0)
    with pytest.raises(ValueError, match=r"^car.gap must be >= 0, got -1$"):
        check_non_negative("car", gap=-1)


def test_numeric_fields_of_a_record():
    @dataclass
    class Rec:
        a: float = 1.0
        b: int = 2
        name: str = "x"

    check_numeric_fields_finite("rec", Rec())
    with pytest.raises(ValueError, match=r"rec.a must be a finite number, got inf"):
        check_numeric_fields_finite("rec", Rec(a=math.inf))
    with pytest.raises(ValueError, match=r"rec.b must be a finite number, got 'two'"):
        check_numeric_fields_finite("rec", Rec(b="two"))


def test_one_enum_error_format():
    assert parse_enum(Colour, "red", "colour") is Colour.RED
    assert parse_enum(Colour, Colour.GREEN, "colour") is Colour.GREEN
    with pytest.raises(ValueError, match=r"^unknown colour 'blue'; allowed: red, green$"):
        parse_enum(Colour, "blue", "colour")
    with pytest.raises(ValueError, match=r"^car.paint: unknown colour 'blue'; allowed: red, green$"):
        parse_enum(Colour, "blue", "colour", "car.paint")


def test_array_checks_name_the_first_bad_entry():
    assert finite_array("x", [1, 2]).dtype == float
    with pytest.raises(ValueError, match=r"^x must be finite numbers, got nan at index \(1,\)$"):
        finite_array("x", [1.0, math.nan])
    with pytest.raises(ValueError, match=r"^dv must be finite and >= 0 \[m/s\], got -1.0 at index \(0, 1\)$"):
        non_negative_array("dv", [[0.0, -1.0]], "[m/s]")
    with pytest.raises(ValueError, match=r"^m must be finite and > 0 \[kg\], got 0.0$"):
        positive_array("m", 0.0, "[kg]")
    with pytest.raises(ValueError, match=r"^v must have shape \(..., 2\) \[m/s\], got shape \(3,\)$"):
        vector_array("v", [1, 2, 3], "[m/s]")
    with pytest.raises(ValueError, match=r"^p must have shape \(n, 2\) = \(3, 2\), got \(2, 2\)$"):
        shaped_array("p", np.zeros((2, 2)), "(n, 2)", 2, (3, 2))
    with pytest.raises(ValueError, match=r"^p must have shape \(n, 2\), got \(2,\)$"):
        shaped_array("p", np.zeros(2), "(n, 2)", 2)


@dataclass(frozen=True)
class Inner:
    speed: float = 1.0
    colour: Colour = Colour.RED

    def __post_init__(self):
        object.__setattr__(self, "colour", parse_enum(Colour, self.colour, "colour", "inner.colour"))
        check_positive("inner", speed=self.speed)


@dataclass(frozen=True)
class Outer:
    name: str
    count: int = 1
    inner: Inner = field(default_factory=Inner)
    items: tuple[Inner, ...] = ()
    values: tuple[float, ...] = (1.0,)


def test_loader_builds_nested_records_and_names_every_bad_field():
    outer = from_mapping(Outer, {"name": "a", "inner": {"speed": 2}, "items": [{}, {"colour": "green"}]})
    assert outer.inner == Inner(2.0) and isinstance(outer.inner.speed, float)
    assert outer.items[1].colour is Colour.GREEN
    cases = [
        ({"name": "a", "bogus": 1}, r"^unknown key 'bogus'; allowed: count, inner, items, name, values$"),
        ({"name": "a", "inner": {"sped": 1}}, r"^unknown key 'inner.sped'; allowed: colour, speed$"),
        ({"name": "a", "items": [{}, {"speed": -1}]}, r"^items\[1\]: inner.speed must be > 0, got -1.0$"),
        ({"name": "a", "items": [{"colour": "blue"}]}, r"^items\[0\]: inner.colour: unknown colour 'blue'"),
        ({"count": 2}, r"^missing key 'name'$"),
        ({"name": "a", "count": 1.5}, r"^count must be an integer, got 1.5$"),
        ({"name": "a", "values": 2.0}, r"^values must be a list, got 2.0$"),
        ({"name": "a", "inner": 3}, r"^inner must be a table of keys, got 3$"),
    ]
    for data, message in cases:
        with pytest.raises(ValueError, match=message):
            from_mapping(Outer, data)


def test_loader_overrides_a_base_record_key_by_key():
    base = Outer("base", 3, Inner(5.0, Colour.GREEN))
    changed = from_mapping(Outer, {"inner": {"speed": 7.0}}, base=base)
    assert changed == Outer("base", 3, Inner(7.0, Colour.GREEN))
    assert base.inner.speed == 5.0


def test_toml_errors_name_the_file(tmp_path):
    path = tmp_path / "x.toml"
    path.write_text('name = "a"\n[inner]\nspeed = "fast"\n')
    data = read_toml(path, "example")
    with pytest.raises(ValueError, match=r"x.toml: inner.speed must be a finite number, got 'fast'"):
        with errors_in(path):
            from_mapping(Outer, data)
    with pytest.raises(ValueError, match="cannot read example file .*missing.toml"):
        read_toml(tmp_path / "missing.toml", "example")
    path.write_text("name = \n")
    with pytest.raises(ValueError, match="x.toml: not valid TOML"):
        read_toml(path, "example")


def test_non_finite_floats_and_tables_survive_the_round_trip():
    @dataclass(frozen=True)
    class Record:
        low: float
        high: float
        missing: float
        per_group: dict[str, float]
        pair: tuple[float, float]

    record = Record(-math.inf, math.inf, math.nan, {"ego": math.inf, "vru": 1}, (math.nan, 2))
    plain = to_plain(record)
    assert plain == {
        "low": "-inf",
        "high": "inf",
        "missing": "nan",
        "per_group": {"ego": "inf", "vru": 1},
        "pair": ["nan", 2],
    }
    back = from_mapping(Record, plain)
    assert (back.low, back.high, back.per_group["ego"]) == (-math.inf, math.inf, math.inf)
    assert math.isnan(back.missing) and math.isnan(back.pair[0])
    assert back.per_group["vru"] == 1.0 and isinstance(back.per_group["vru"], float)
    assert back.pair[1] == 2.0 and isinstance(back.pair[1], float)


def test_to_plain_is_json_ready():
    @dataclass
    class Plain:
        speed: float
        colour: Colour
        values: tuple
        array: np.ndarray

    plain = to_plain(Plain(math.inf, Colour.GREEN, (np.float64(2.0), Inner()), np.array([[1, 2]])))
    assert plain == {
        "speed": "inf",
        "colour": "green",
        "values": [2.0, {"speed": 1.0, "colour": "red"}],
        "array": [[1, 2]],
    }
