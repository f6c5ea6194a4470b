"""JSON Schemas derived from the message dataclasses, and the JSON codec (encoding 2, and
encoding 1 as files written before it hold it)."""

from __future__ import annotations

import dataclasses
import json
import math

import jsonschema
import pytest
from session_helpers import FIXTURES, example_message, same

from ucat_console.robot.readings import ImuReading
from ucat_console.backend.sessions import codec, foxglove, legacy
from ucat_console.backend.sessions.schema import (
    DIALECT,
    field_specs,
    json_schema,
    schema_encoding,
    schema_name,
)
from ucat_console.backend.sessions import images
from ucat_console.telemetry.channels import CHANNELS
from ucat_console.telemetry.events import Event
from ucat_console.robot.fields import field_docs
from ucat_console.telemetry.messages import BodyState, FinPlan, FinState, Power, Setpoints, Status

# the channels written with a derived schema (the camera's pictures are foxglove.CompressedImage)
TYPES = sorted({c for c in CHANNELS.values() if not images.is_image(c)}, key=lambda c: c.__name__)
BIG_SEED = 17029223188912930816  # > 2^53: a JavaScript number would round it


def test_setpoints_schema_is_the_hand_written_one():
    s = json_schema(Setpoints)
    assert s["$schema"] == DIALECT
    assert s["$id"] == "urn:ucat-console:telemetry:2:Setpoints"
    assert s["title"] == "ucat_console.Setpoints"
    assert s["type"] == "object" and s["additionalProperties"] is False
    nonfinite = s["properties"].pop("nonfinite")
    assert s["properties"] == {
        "t": {"type": "number", "unit": "s", "description": "time on the stream's clock (unit s)"},
        "velocity": {"type": "number", "unit": "m/s", "description": "forward velocity setpoint (unit m/s)"},
        "depth": {"type": "number", "unit": "m", "description": "depth setpoint (unit m)"},
        "yaw_rate": {"type": "number", "unit": "rad/s", "description": "yaw rate setpoint, positive clockwise "
                                                                       "seen from above (unit rad/s; frame NED)"},
    }
    assert nonfinite["type"] == "object" and nonfinite["properties"] == {}
    assert nonfinite["additionalProperties"] == {"type": "string", "enum": ["nan", "inf", "-inf"]}
    assert s["required"] == []  # a non-finite float is left out, so no float is required


def test_vectors_are_named_quaternions_x_y_z_w_per_fin_values_stay_arrays():
    body = json_schema(BodyState)["properties"]
    assert body["position"]["properties"] == {n: {"type": "number", "unit": "m"} for n in "xyz"}
    assert body["position"]["title"] == "foxglove.Vector3"
    assert "NED" in body["position"]["description"] and "unit m" in body["position"]["description"]
    assert list(body["orientation"]["properties"]) == ["x", "y", "z", "w"]
    assert body["orientation"]["title"] == "foxglove.Quaternion"
    per_fin = json_schema(Power)["properties"]["per_fin"]
    assert per_fin["type"] == "array" and per_fin["minItems"] == per_fin["maxItems"] == 4
    assert per_fin["prefixItems"] == [{"type": ["number", "null"], "unit": "W"}] * 4
    assert per_fin["items"] == {"type": "number"}
    plan = json_schema(FinPlan)["properties"]
    assert list(plan["u"]["properties"]) == ["d_1", "d_2", "w_1", "w_2"]
    assert plan["seed"]["type"] == "string" and plan["seed"]["pattern"] == "^-?[0-9]+$"
    assert "2^53" in plan["seed"]["description"]
    fin = json_schema(FinState)
    assert fin["properties"]["fin"]["type"] == "integer"
    assert fin["required"] == ["fin"]
    status = json_schema(Status)["properties"]
    assert status["armed"]["type"] == "boolean"
    assert status["failsafes"]["items"] == {"type": "string"}
    imu = json_schema(ImuReading)
    assert "quaternion" not in imu["required"]  # optional: left out when None
    assert list(imu["properties"]["euler"]["properties"]) == ["roll", "pitch", "yaw"]
    assert json_schema(Event)["properties"]["data"]["type"] == "object"


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_every_field_says_what_it_is(cls):
    docs = field_docs(cls)
    assert set(docs) == {f.name for f in dataclasses.fields(cls)}
    for name, prop in json_schema(cls)["properties"].items():
        assert prop.get("description"), name


def _foxglove_readable(schema: dict, where: str) -> None:
    """The rules of Foxglove's and Lichtblick's JSON Schema reader (parseJsonSchema): one
    type name per field, objects with properties, arrays with one item type (objects
    again checked); Foxglove also takes an enumeration of numbers (oneOf of consts)."""
    assert schema["type"] == "object", where
    for name, prop in schema["properties"].items():
        if "oneOf" in prop:
            assert all(isinstance(x["const"], int) for x in prop["oneOf"]), f"{where}.{name}"
            continue
        assert isinstance(prop.get("type"), str), f"{where}.{name}"
        if prop["type"] == "object":
            _foxglove_readable(prop, f"{where}.{name}")
        if prop["type"] == "array":
            assert isinstance(prop["items"]["type"], str), f"{where}.{name}"
            if prop["items"]["type"] == "object":
                _foxglove_readable(prop["items"], f"{where}.{name}[]")


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_schema_is_readable_by_foxglove_and_valid_json_schema(cls):
    s = json_schema(cls)
    jsonschema.Draft202012Validator.check_schema(s)
    _foxglove_readable(s, cls.__name__)
    assert schema_encoding(s) == 2


@pytest.mark.parametrize("topic", sorted(foxglove.DERIVED_TOPICS))
def test_the_foxglove_schemas_are_the_official_ones_and_readable_by_foxglove(topic):
    name = foxglove.DERIVED_TOPICS[topic]
    schema = foxglove.official_schema(name)
    assert schema["title"] == name
    official = FIXTURES / "foxglove" / f"{name.removeprefix('foxglove.')}.json"
    if official.exists():  # the copies Foxglove publishes, kept beside the tests
        assert schema == json.loads(official.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    _foxglove_readable(schema, topic)


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_every_message_type_round_trips_with_nan(cls):
    msg = example_message(cls, k=1)
    data = codec.encode(msg)
    obj = json.loads(data)  # strict JSON: no NaN tokens
    jsonschema.validate(obj, json_schema(cls), cls=jsonschema.Draft202012Validator)
    back = codec.decode(cls, data)
    assert same(back, msg)


def test_non_finite_numbers_are_left_out_and_listed_by_path():
    msg = BodyState(1.5, (1.0, math.nan, math.inf), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                    (0.0, 0.0, -math.inf), math.nan)
    text = codec.encode(msg).decode()
    assert "1e999" not in text and "NaN" not in text and "Infinity" not in text
    obj = json.loads(text)
    assert "depth" not in obj
    assert obj["position"] == {"x": 1.0}
    assert obj["orientation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    assert obj["nonfinite"] == {"position.y": "nan", "position.z": "inf", "rates.z": "-inf",
                                "depth": "nan"}
    back = codec.decode(BodyState, text.encode())
    assert math.isnan(back.depth) and math.isnan(back.position[1])
    assert back.position[2] == math.inf and back.rates[2] == -math.inf
    assert back.orientation == (1.0, 0.0, 0.0, 0.0)  # w first again
    power = Power(2.0, (0.1, math.inf, 0.3, 0.4), 1.0, 0.5, 3.0, 0.0, math.nan)
    obj = json.loads(codec.encode(power))
    assert obj["per_fin"] == [0.1, None, 0.3, 0.4]
    assert obj["nonfinite"] == {"per_fin[1]": "inf", "energy_per_metre": "nan"}
    assert same(codec.decode(Power, codec.encode(power)), power)


def test_large_finite_numbers_whose_sum_is_not_finite_are_kept():
    big = 1.7e308  # finite; two of them add up to inf
    msg = BodyState(1.0, (big, big, -big), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (big, big, 0.0), 2.0)
    obj = json.loads(codec.encode(msg))
    assert "nonfinite" not in obj
    assert obj["position"] == {"x": big, "y": big, "z": -big}
    power = Power(2.0, (big, big, 0.3, 0.4), 1.0, 0.5, 3.0, 0.0, 1.0)
    assert json.loads(codec.encode(power))["per_fin"] == [big, big, 0.3, 0.4]
    assert same(codec.decode(BodyState, codec.encode(msg)), msg)


def test_a_seed_beyond_2_53_is_a_string_and_comes_back_exact():
    plan = example_message(FinPlan, k=2, nan=False)
    plan = dataclasses.replace(plan, seed=BIG_SEED)
    obj = json.loads(codec.encode(plan))
    assert obj["seed"] == "17029223188912930816"
    assert codec.decode(FinPlan, codec.encode(plan)).seed == BIG_SEED
    none = dataclasses.replace(plan, seed=-1)
    assert codec.decode(FinPlan, codec.encode(none)).seed == -1


def test_empty_text_and_empty_lists_stay_empty():
    status = Status(1.0, False, "mpc", "", (), 0, "sim")
    obj = json.loads(codec.encode(status))
    assert obj["pilot"] == "" and obj["failsafes"] == []
    assert codec.decode(Status, codec.encode(status)) == status


def test_optional_tuple_none_is_left_out_and_read_back_as_none():
    msg = ImuReading(0.5, (0.0, 0.0, -1.0), (0.1, 0.2, 0.3))
    obj = json.loads(codec.encode(msg))
    assert "quaternion" not in obj and "euler" not in obj
    assert codec.decode(ImuReading, codec.encode(msg)) == msg


def test_event_data_non_finite_becomes_null():
    ev = Event(2.0, "imu", "invalid_data", "bad", "error", {"x": math.nan, "y": [1.0, math.inf]})
    back = codec.decode(Event, codec.encode(ev))
    assert back.data == {"x": None, "y": [1.0, None]}


@pytest.mark.parametrize(
    "data, needle",
    [
        (b"{not json", "not valid JSON"),
        (b"[1, 2]", "expected a JSON object"),
        (b'{"t": 1.0, "fin": "two"}', "FinState.fin: expected an integer"),
        (b'{"t": 1.0, "fin": 1, "angle": "x"}', "FinState.angle: expected a number"),
        (b'{"t": 1.0, "fin": 1, "angle": null}', "FinState.angle: expected a number"),
        (b'{"t": 1.0, "fin": 1, "spin": 3}', "FinState.spin: unknown field"),
        (b'{"t": 1.0}', "FinState.fin: missing"),
        (b'{"t": 1.0, "fin": 1, "rate": 0, "angle_cmd": 0, "rate_cmd": 0}',
         "FinState.angle: missing"),  # a number left out must be listed as non-finite
        (b'{"t": 1.0, "fin": 1, "angle": 0, "rate": 0, "angle_cmd": 0, "rate_cmd": 0,'
         b' "nonfinite": {"angle": "nan"}}', "'angle' names no missing value"),
        (b'{"t": 1.0, "fin": 1, "rate": 0, "angle_cmd": 0, "rate_cmd": 0,'
         b' "nonfinite": {"angle": "huge"}}', "expected an object of nan / inf / -inf"),
    ],
)
def test_decode_names_the_bad_field(data, needle):
    with pytest.raises(ValueError, match=needle):
        codec.decode(FinState, data)


def test_decode_checks_vectors_wide_integers_and_event_level():
    good = json.loads(codec.encode(example_message(BodyState, nan=False)))
    with pytest.raises(ValueError, match=r"BodyState.position.q: unknown field"):
        codec.decode(BodyState, json.dumps({**good, "position": {"x": 1, "q": 2}}).encode())
    with pytest.raises(ValueError, match=r"BodyState.position: expected an object of x, y, z"):
        codec.decode(BodyState, json.dumps({**good, "position": [1, 2, 3]}).encode())
    plan = json.loads(codec.encode(example_message(FinPlan, nan=False)))
    with pytest.raises(ValueError, match="FinPlan.seed: expected an integer as a decimal string"):
        codec.decode(FinPlan, json.dumps({**plan, "seed": 3}).encode())
    with pytest.raises(ValueError, match="level"):
        codec.decode(Event, b'{"t":0,"source":"a","code":"b","message":"c","level":"loud",'
                            b'"data":{}}')


def test_encode_refuses_a_wrong_kind_naming_the_field():
    bad = FinState(0.0, 1, "not a number", 0.0, 0.0, 0.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="FinState.angle"):
        codec.encode(bad)


def test_encoding_1_objects_decode_to_the_same_messages():
    """What files written before encoding 2 hold: arrays, 1e999, a missing NaN scalar, a
    null NaN element, a numeric seed (written here by hand as that codec wrote them)."""
    body = (b'{"t":1.5,"position":[1.0,null,1e999],"orientation":[1.0,0.0,0.0,0.0],'
            b'"velocity":[0.0,0.0,0.0],"rates":[0.0,0.0,-1e999]}')
    back = legacy.decode(BodyState, body)
    assert same(back, BodyState(1.5, (1.0, math.nan, math.inf), (1.0, 0.0, 0.0, 0.0),
                                (0.0, 0.0, 0.0), (0.0, 0.0, -math.inf), math.nan))
    plan = json.loads(codec.encode(example_message(FinPlan, nan=False)))
    old = {**plan, "seed": 12345, "target": [plan["target"]["x"], plan["target"]["y"]]}
    for name in ("u_prev", "u", "commands", "mean_force"):
        old[name] = list(plan[name].values())
    assert legacy.decode(FinPlan, json.dumps(old).encode()).seed == 12345
    with pytest.raises(ValueError, match="BodyState.position: expected an array of 3"):
        legacy.decode(BodyState, b'{"t":0,"position":[1,2],"orientation":[1,0,0,0],'
                                  b'"velocity":[0,0,0],"rates":[0,0,0]}')


def test_time_conversion_is_exact_for_simulated_times_under_an_epoch_offset():
    assert codec.to_ns(0.125, 1_700_000_000.0) == 1_700_000_000_125_000_000
    assert codec.to_ns(1_700_000_000.5) == 1_700_000_000_500_000_000
    assert codec.from_ns(1_700_000_000_125_000_000, 1_700_000_000.0) == 0.125
    assert schema_name(BodyState) == "ucat_console.BodyState"
    assert [s.paths() for s in field_specs(Power)][1] == [f"per_fin[{i}]" for i in range(4)]


def _field_values(spec):
    """Values of one field as a message may carry them: the common ones, and those the
    general encoder converts (ints and numpy floats for floats, lists for tuples), refuses,
    or leaves out (non-finite numbers, None for an optional field)."""
    import numpy as np
    from hypothesis import strategies as st

    from ucat_console.backend.sessions.schema import BOOL, FLOAT, FLOATS, INT, STR

    number = st.one_of(
        st.floats(allow_nan=True, allow_infinity=True),
        st.sampled_from([0.0, -0.0, 1.7e308, -1.7e308, 5e-324]),
        st.integers(-10, 10),
        st.floats(allow_nan=False, width=64).map(np.float64),
    )
    if spec.kind == FLOAT:
        values = number
    elif spec.kind == FLOATS:
        n = spec.length
        values = st.one_of(
            st.tuples(*[number] * n),
            st.lists(number, min_size=n, max_size=n),
            st.tuples(*[number] * (n + 1)),  # the wrong length: refused
        )
    elif spec.kind == INT:
        values = st.one_of(st.integers(), st.booleans(), st.just(1.0))
    elif spec.kind == BOOL:
        values = st.one_of(st.booleans(), st.integers(0, 1))
    elif spec.kind == STR:
        values = st.one_of(st.text(max_size=8), st.integers(0, 3))
    else:
        values = st.nothing()
    return st.one_of(values, st.none()) if spec.optional else values


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_the_fast_encoder_gives_what_the_general_one_gives(cls):
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from ucat_console.backend.sessions.schema import JSON, SEQ

    specs = field_specs(cls)
    fast = codec._encoder(cls)
    general = codec._make_encoder(cls)
    if any(s.kind in (SEQ, JSON) for s in specs):
        assert fast.__code__ is general.__code__  # no fast path for these kinds
        return
    assert fast.__code__ is not general.__code__

    def outcome(enc, msg):
        try:
            obj = enc(msg)
        except ValueError as e:
            return "refused", str(e)
        return "encoded", codec.compact_json(obj)

    @settings(max_examples=300, deadline=None)
    @given(st.fixed_dictionaries({s.name: _field_values(s) for s in specs}))
    def check(values):
        msg = object.__new__(cls)  # any values, as a message built elsewhere may hold them
        for name, v in values.items():
            object.__setattr__(msg, name, v)
        assert outcome(fast, msg) == outcome(general, msg)

    check()
    common = example_message(cls, k=3, nan=False)
    assert outcome(fast, common) == outcome(general, common)
    assert outcome(fast, common)[0] == "encoded"


def _units(schema: dict, where: str, out: dict[str, str]) -> dict[str, str]:
    """Every ``unit`` keyword of a schema, by path."""
    if "unit" in schema:
        out[where] = schema["unit"]
    for name, prop in schema.get("properties", {}).items():
        _units(prop, f"{where}.{name}", out)
    for i, item in enumerate(schema.get("prefixItems", [])):
        _units(item, f"{where}[{i}]", out)
    return out


def test_every_unit_of_the_schemas_is_one_pint_parses_and_each_vector_part_has_its_own():
    pint = pytest.importorskip("pint")
    ureg = pint.UnitRegistry()
    seen = {}
    for cls in TYPES:
        seen.update(_units(json_schema(cls), cls.__name__, {}))
    for where, unit in seen.items():
        ureg.parse_units(unit)  # raises on a unit pint does not know
        assert unit != "g", where  # grams: never meant here
    # one unit per part, SI
    assert seen["FinPlan.u.d_1"] == "rad" and seen["FinPlan.u.w_2"] == "rad/s"
    assert seen["FinPlan.commands.theta_2"] == "rad" and seen["FinPlan.commands.w_1"] == "rad/s"
    assert seen["BodyState.position.z"] == "m" and seen["BodyState.rates.x"] == "rad/s"
    assert seen["Power.per_fin[3]"] == "W" and seen["ElectricalPower.current[0]"] == "A"
    assert seen["ImuReading.accel.z"] == "m/s^2"  # SI, not standard gravities
    assert ureg.Quantity(2.0, seen["BodyAllocation.yaw"]).to("J").magnitude == pytest.approx(2.0)  # N m
    # every number whose field documents a unit carries it
    for cls in TYPES:
        for name, doc in field_docs(cls).items():
            if doc.unit:
                assert any(p == f"{cls.__name__}.{name}" or p.startswith(f"{cls.__name__}.{name}.")
                           or p.startswith(f"{cls.__name__}.{name}[") for p in seen), (cls.__name__, name)


# ------------------------------------------------------------------ fields renamed since a session was recorded
def test_an_imu_reading_recorded_in_standard_gravities_opens_in_metres_per_second_squared() -> None:
    """Sessions recorded before the IMU's acceleration was in m/s^2 hold ``accel_g`` in
    standard gravities: both encodings read it as ``accel`` times g0 = 9.80665 m/s^2, a
    non-finite part staying non-finite."""
    old2 = json.dumps({"t": 1.5, "accel_g": {"x": 0.5, "z": -1.0}, "gyro": {"x": 0.0, "y": 0.0, "z": 0.25},
                       "nonfinite": {"accel_g.y": "nan"}}).encode()
    r = codec.decode(ImuReading, old2)
    assert r.accel[0] == pytest.approx(4.903325, rel=1e-15) and r.accel[2] == pytest.approx(-9.80665, rel=1e-15)
    assert math.isnan(r.accel[1]) and r.gyro == (0.0, 0.0, 0.25)
    old1 = json.dumps({"t": 1.5, "accel_g": [0.5, None, -1.0], "gyro": [0.0, 0.0, 0.25]}).encode()
    r1 = legacy.decode(ImuReading, old1)
    assert r1.accel[0] == pytest.approx(4.903325, rel=1e-15) and math.isnan(r1.accel[1])
    # a present-day message is read as it is, and one with both names is refused, naming the field
    now = codec.encode(ImuReading(2.0, (0.1, 0.2, -9.8), (0.0, 0.0, 0.0)))
    assert codec.decode(ImuReading, now).accel == (0.1, 0.2, -9.8)
    both = json.dumps({"t": 1.5, "accel": {"x": 0.0, "y": 0.0, "z": -9.8}, "accel_g": {"x": 0.0, "y": 0.0, "z": -1.0},
                       "gyro": {"x": 0.0, "y": 0.0, "z": 0.0}}).encode()
    with pytest.raises(ValueError, match="accel_g"):
        codec.decode(ImuReading, both)


def test_the_camera_channel_has_the_official_compressed_image_schema():
    schema = json.loads(images.schema_bytes())
    assert schema["title"] == images.SCHEMA == "foxglove.CompressedImage"
    assert schema == json.loads((FIXTURES / "foxglove" / "CompressedImage.json").read_text())
    assert schema["properties"]["data"]["contentEncoding"] == "base64"
    jsonschema.Draft202012Validator.check_schema(schema)
    _foxglove_readable(schema, "camera/image")
