"""Hypothesis properties of the input parsers and the API: any value either converts to a
finite SI float (or the documented value) or raises :class:`InputError` naming the key,
never another exception; no quantity string is evaluated; numpy scalars are numbers.

CI runs a bounded number of examples (``max_examples`` below); the ``slow`` test runs the
same properties at full size.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import braidsim
from braidsim.errors import InputError
from braidsim.params import SCHEMA, convert, parse_set_value
from braidsim.units import parse_quantity, to_si
from fuzz.harness import RECORD, judge, run_cli

FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FULL = settings(max_examples=3000, deadline=None, suppress_health_check=[HealthCheck.too_slow])

UNITS = ["m", "mm", "nm", "km", "s", "ms", "kg", "N", "GPa", "rpm", "Hz", "deg", "rad", "%"]
OPS = ["", " ", "*", "/", "^", "**", "(", ")", "==", "+", "-", "e", ".", "_", "9", "1e400"]

#: anything a user might type for a value
quantity_text = st.one_of(
    st.text(max_size=40),
    st.lists(
        st.sampled_from(UNITS + OPS + ["1", "2.5", "-3", "1e9", "nan", "inf"]), max_size=8
    ).map("".join),
    st.builds(
        lambda x, u: f"{x} {u}",
        st.floats(allow_nan=True, allow_infinity=True),
        st.sampled_from(UNITS),
    ),
)
raw_values = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**400), max_value=10**400),
    st.floats(allow_nan=True, allow_infinity=True),
    quantity_text,
    st.lists(st.floats(allow_nan=True), max_size=3),
    st.lists(st.lists(st.one_of(st.floats(), quantity_text), max_size=4), max_size=3),
    st.dictionaries(st.sampled_from(["times", "speeds", "x"]), st.lists(st.floats(), max_size=3)),
    st.builds(np.float32, st.floats(width=32)),
    st.builds(np.int64, st.integers(min_value=-(2**63), max_value=2**63 - 1)),
    st.sampled_from([object(), b"3 mm", 3j, np.array([1.0, 2.0]), {1, 2}]),
)


def _record(name: str, ok: bool, why: str = "") -> None:
    RECORD.add(name, None if ok else why)


def _check_to_si(text: str, unit: str) -> None:
    try:
        v, _ = parse_quantity("k", text, unit)
    except InputError as exc:
        assert str(exc).startswith("k:"), exc
        assert "\n" not in str(exc)
    else:
        assert isinstance(v, float)
        assert math.isfinite(v) or "inf" in text.lower() or "nan" in text.lower()


def _check_convert(key: str, value: object) -> None:
    spec = SCHEMA[key]
    try:
        out = convert(spec, value)
    except InputError as exc:
        assert str(exc).startswith(key), exc
        assert "\n" not in str(exc)
        return
    if spec.kind == "float" and out is not None:
        assert isinstance(out, float)
        assert math.isfinite(out) or (spec.allow_inf and math.isinf(out))
    if spec.kind == "int":
        assert isinstance(out, int) and spec.low <= out <= spec.high


@FAST
@given(text=quantity_text, unit=st.sampled_from(["m", "s", "rad/s", "", "N/m**1.5", "Pa"]))
def test_quantity_strings_convert_or_refuse(text, unit):
    _check_to_si(text, unit)


@FAST
@given(key=st.sampled_from(sorted(SCHEMA)), value=raw_values)
def test_every_key_converts_or_refuses_naming_it(key, value):
    _check_convert(key, value)


@FAST
@given(key=st.sampled_from(sorted(SCHEMA)), text=st.text(max_size=60))
def test_set_values_convert_or_refuse(key, text):
    """``--set KEY=TEXT`` as the command line reads it."""
    _check_convert(key, parse_set_value(key, text))


@pytest.mark.slow
@FULL
@given(
    key=st.sampled_from(sorted(SCHEMA)),
    value=raw_values,
    text=quantity_text,
    unit=st.sampled_from(["m", "s", "rad/s", "", "N/m**1.5"]),
)
def test_full_size_properties(key, value, text, unit):
    _check_to_si(text, unit)
    _check_convert(key, value)
    _check_convert(key, parse_set_value(key, text))


@FAST
@given(
    data=st.recursive(
        st.one_of(st.floats(), st.text(max_size=8), st.integers(), st.booleans(), st.none()),
        lambda children: st.one_of(
            st.lists(children, max_size=3),
            st.dictionaries(st.text(max_size=6), children, max_size=3),
        ),
        max_leaves=20,
    )
)
def test_load_scenario_mapping_converts_or_refuses(data):
    try:
        braidsim.load_scenario(data if isinstance(data, dict) else {"track.clearance": data})
    except InputError as exc:
        assert "\n" not in str(exc)


def test_sweep_spec_parser_refuses_cleanly():
    """Random mutations of a valid spec table: each parses or raises one InputError."""
    from hypothesis import find  # noqa: F401  (documents that hypothesis drives the search)

    from braidsim.sweep import parse_spec

    @FAST
    @given(
        mutation=st.dictionaries(
            st.sampled_from(
                [
                    "scenario",
                    "duration",
                    "axes",
                    "samples",
                    "metrics",
                    "series",
                    "execution",
                    "nope",
                ]
            ),
            st.one_of(
                raw_values,
                st.lists(
                    st.dictionaries(
                        st.sampled_from(
                            ["key", "name", "values", "start", "stop", "num", "spacing"]
                        ),
                        raw_values,
                        max_size=4,
                    ),
                    max_size=2,
                ),
            ),
            max_size=3,
        )
    )
    def prop(mutation):
        spec = {
            "scenario": "paper-3.1",
            "duration": "0.004 s",
            "axes": [{"key": "track.clearance", "values": ["1 mm", "2 mm"]}],
        }
        spec.update(mutation)
        try:
            parse_spec(spec)
        except InputError as exc:
            assert "\n" not in str(exc)

    prop()


SPEC_TABLES = st.dictionaries(
    st.sampled_from(
        [
            "name",
            "scenario",
            "machine",
            "braid",
            "animation",
            "revolutions",
            "duration",
            "design",
            "machine_spec",
            "overrides",
        ]
    ),
    st.one_of(raw_values, st.dictionaries(st.text(max_size=10), raw_values, max_size=3)),
    max_size=4,
)


def _refuses_cleanly(parser) -> None:
    @FAST
    @given(table=SPEC_TABLES)
    def prop(table):
        try:
            parser(table, None)
        except InputError as exc:
            assert "\n" not in str(exc)

    prop()


def test_machine_spec_parser_refuses_cleanly():
    from braidsim.machine.spec import parse_machine_spec

    _refuses_cleanly(parse_machine_spec)


def test_design_spec_parser_refuses_cleanly():
    from braidsim.design.spec import parse_design_spec

    _refuses_cleanly(parse_design_spec)


# -------------------------------------------------------------------- fixed API cases


def test_numpy_scalars_are_numbers():
    sc = braidsim.load_scenario(
        {"track.clearance": np.float32(0.003), "simulation.max_steps": np.int64(1000)}
    )
    assert sc["simulation.max_steps"] == 1000
    assert sc["track.clearance"] == pytest.approx(0.003, rel=1e-6)
    assert to_si("k", np.float64(2.5), "m") == 2.5


@pytest.mark.parametrize(
    ("overrides", "key"),
    [
        ({"track.clearance": None}, "track.clearance"),
        ({"track.clearance": "1 m == 0.002"}, "track.clearance"),
        ({"track.clearance": "9**9**9 m"}, "track.clearance"),
        ({"track.clearance": "10**400 m"}, "track.clearance"),
        ({"track.clearance": 10**400}, "track.clearance"),
        ({"track.clearance": [1]}, "track.clearance"),
        ({"track.clearance": object()}, "track.clearance"),
        ({"simulation.max_steps": math.nan}, "simulation.max_steps"),
        ({"simulation.max_steps": math.inf}, "simulation.max_steps"),
        ({"simulation.max_steps": 1e300}, "simulation.max_steps"),
        ({"horn_gear.speed_profile": {"times": 1, "speeds": 2}}, "horn_gear.speed_profile"),
        ({"horn_gear.speed_harmonics": 5}, "horn_gear.speed_harmonics"),
        ({"track.harmonics": [[1, 2, 3, 4]]}, "track.harmonics"),
        ({"friction.law": 3}, "friction.law"),
        ({"contact.allow_tension": "maybe"}, "contact.allow_tension"),
        ({"transfer.times": {"a": 1}}, "transfer.times"),
        ({"carrier": {"mass": {"deeper": {"still": 1}}}}, "carrier.mass"),
    ],
)
def test_api_type_errors_are_one_line_input_errors(overrides, key):
    with pytest.raises(InputError) as info:
        braidsim.load_scenario(overrides)
    msg = str(info.value)
    RECORD.add(
        f"api-{key}-{type(next(iter(overrides.values()))).__name__}", None if key in msg else msg
    )
    assert key in msg and "\n" not in msg


def test_none_is_absent_only_for_keys_absent_by_default():
    sc = braidsim.load_scenario({"contact.track.stiffness": None})
    assert sc["contact.track.stiffness"] is None


def test_deep_nesting_of_a_mapping_is_refused():
    d: dict = {"x": 1}
    for _ in range(200):
        d = {"a": d}
    with pytest.raises(InputError, match="nested"):
        braidsim.load_scenario(d)


def test_extends_is_relative_to_the_file(tmp_path, monkeypatch):
    sub = tmp_path / "dir"
    sub.mkdir()
    (sub / "base.toml").write_text('extends = "paper-3.1"\n[track]\nclearance = "2 mm"\n')
    (sub / "child.toml").write_text('extends = "base.toml"\n[carrier]\nmass = "2 kg"\n')
    monkeypatch.chdir(tmp_path)  # not the folder of the files
    sc = braidsim.load_scenario(sub / "child.toml")
    assert sc["track.clearance"] == pytest.approx(2e-3)
    assert sc["carrier.mass"] == 2.0


def test_the_harness_flags_what_it_must():
    """The judge is not vacuous: success, tracebacks, two lines and exit codes are flagged."""
    code, out, err = run_cli(["models", "--json"])
    assert code == 0 and judge(code, out, err, (2,), ()) is not None
    assert judge(1, "", "Traceback (most recent call last):\nX\n", (1,), ()) is not None
    assert judge(2, "", "braidsim: error: a\nbraidsim: error: b\n", (2,), ()) is not None
    assert judge(2, "", "braidsim: error: internal error: X\n", (2,), ()) is not None
    assert judge(2, "", "braidsim: error: x: bad\n", (2,), ("y",)) is not None
    assert judge(2, "", "braidsim: error: x: bad\n", (2,), ("x",)) is None


@pytest.mark.parametrize(
    ("scenario", "overrides", "fragment"),
    [
        (123, None, "scenario"),
        (None, None, "scenario"),
        ("paper-3.1", [("track.clearance", 1)], "overrides"),
        ("paper-3.1", {1: 2}, "1"),
    ],
)
def test_wrong_argument_types_are_input_errors(scenario, overrides, fragment):
    with pytest.raises(InputError, match=fragment):
        braidsim.load_scenario(scenario, overrides=overrides)
