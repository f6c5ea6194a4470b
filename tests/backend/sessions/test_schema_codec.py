"""JSON Schemas derived from the message dataclasses, and the JSON codec."""

from __future__ import annotations

import json
import math

import jsonschema
import pytest
from session_helpers import example_message, same

from ucat_console.robot.readings import ImuReading
from ucat_console.backend.sessions import codec
from ucat_console.backend.sessions.schema import DIALECT, json_schema, schema_name
from ucat_console.telemetry.channels import CHANNELS
from ucat_console.telemetry.events import Event
from ucat_console.telemetry.messages import BodyState, FinState, Setpoints, Status

TYPES = sorted(set(CHANNELS.values()), key=lambda c: c.__name__)


def test_setpoints_schema_is_the_hand_written_one():
    s = json_schema(Setpoints)
    assert s["$schema"] == DIALECT
    assert s["title"] == "ucat_console.Setpoints"
    assert s["type"] == "object" and s["additionalProperties"] is False
    assert s["properties"] == {
        "t": {"type": "number"},
        "velocity": {"type": "number"},
        "depth": {"type": "number"},
        "yaw_rate": {"type": "number"},
    }
    assert s["required"] == []  # a NaN float is left out, so no float is required


def test_tuples_are_fixed_length_arrays_and_other_kinds_map_one_to_one():
    body = json_schema(BodyState)["properties"]
    assert body["position"]["minItems"] == body["position"]["maxItems"] == 3
    assert body["orientation"]["prefixItems"] == [{"type": ["number", "null"]}] * 4
    assert body["orientation"]["items"] == {"type": "number"}
    fin = json_schema(FinState)
    assert fin["properties"]["fin"] == {"type": "integer"}
    assert fin["required"] == ["fin"]
    status = json_schema(Status)["properties"]
    assert status["armed"] == {"type": "boolean"}
    assert status["mode"] == {"type": "string"}
    assert status["failsafes"] == {"type": "array", "items": {"type": "string"}}
    imu = json_schema(ImuReading)
    assert "quaternion" not in imu["required"]  # optional: left out when None
    assert json_schema(Event)["properties"]["data"]["type"] == "object"


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_schema_is_readable_by_foxglove_and_valid_json_schema(cls):
    """Foxglove/Lichtblick's JSON Schema reader takes one type name per field and a single
    item type per array; anything else makes it reject the channel."""
    s = json_schema(cls)
    jsonschema.Draft202012Validator.check_schema(s)
    for name, prop in s["properties"].items():
        assert isinstance(prop["type"], str), name
        if prop["type"] == "array":
            assert isinstance(prop["items"]["type"], str), name
        if prop["type"] == "object":
            assert isinstance(prop["properties"], dict), name


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_every_message_type_round_trips_with_nan(cls):
    msg = example_message(cls, k=1)
    data = codec.encode(msg)
    obj = json.loads(data)  # strict JSON: no NaN tokens
    jsonschema.validate(obj, json_schema(cls), cls=jsonschema.Draft202012Validator)
    back = codec.decode(cls, data)
    assert same(back, msg)


def test_nan_encoding_scalar_left_out_array_element_null_inf_as_1e999():
    msg = BodyState(1.5, (1.0, math.nan, math.inf), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                    (0.0, 0.0, -math.inf), math.nan)
    text = codec.encode(msg).decode()
    obj = json.loads(text)
    assert "depth" not in obj
    assert obj["position"][1] is None
    assert '"position":[1.0,null,1e999]' in text
    assert '"rates":[0.0,0.0,-1e999]' in text
    back = codec.decode(BodyState, text.encode())
    assert math.isnan(back.depth) and math.isnan(back.position[1])
    assert back.position[2] == math.inf and back.rates[2] == -math.inf


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
        (b'{"t": 1.0, "fin": 1, "spin": 3}', "FinState.spin: unknown field"),
        (b'{"t": 1.0}', "FinState.fin: missing"),
    ],
)
def test_decode_names_the_bad_field(data, needle):
    with pytest.raises(ValueError, match=needle):
        codec.decode(FinState, data)


def test_decode_checks_fixed_lengths_and_event_level():
    with pytest.raises(ValueError, match=r"BodyState.position: expected an array of 3"):
        codec.decode(BodyState, b'{"t":0,"position":[1,2],"orientation":[1,0,0,0],'
                                b'"velocity":[0,0,0],"rates":[0,0,0]}')
    with pytest.raises(ValueError, match="level"):
        codec.decode(Event, b'{"t":0,"source":"a","code":"b","message":"c","level":"loud",'
                            b'"data":{}}')


def test_encode_refuses_a_wrong_kind_naming_the_field():
    bad = FinState(0.0, 1, "not a number", 0.0, 0.0, 0.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="FinState.angle"):
        codec.encode(bad)


def test_time_conversion_is_exact_for_simulated_times_under_an_epoch_offset():
    assert codec.to_ns(0.125, 1_700_000_000.0) == 1_700_000_000_125_000_000
    assert codec.to_ns(1_700_000_000.5) == 1_700_000_000_500_000_000
    assert codec.from_ns(1_700_000_000_125_000_000, 1_700_000_000.0) == 0.125
    assert schema_name(BodyState) == "ucat_console.BodyState"
