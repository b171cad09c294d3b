"""The shipped JSON Schemas are valid schemas of their draft (pwas_hdl.io.json_contract does not
check them on every load: this test does, for every file in pwas_hdl/schemas/)."""

from __future__ import annotations

import json
import re

import jsonschema
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pwas_hdl.errors import InputError
from pwas_hdl.io.json_contract import json_text, load_schema
from pwas_hdl.resources import schemas_dir

SCHEMAS = sorted(p.name for p in schemas_dir().iterdir() if p.name.endswith(".schema.json"))


def test_every_format_has_a_schema():
    assert {"model-v2.schema.json", "manifest-v2.schema.json", "bench-results-v1.schema.json",
            "breakpoints-v1.schema.json", "estimator-v1.schema.json", "explore-v1.schema.json"} <= set(SCHEMAS)


@pytest.mark.parametrize("name", SCHEMAS)
def test_shipped_schema_is_valid_under_its_metaschema(name):
    schema = json.loads((schemas_dir() / name).read_text(encoding="utf-8"))
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    jsonschema.validators.validator_for(schema).check_schema(schema)
    assert load_schema(name) == schema


def test_a_broken_schema_is_caught_by_the_metaschema_check():
    """The check above can fail: a schema with a wrong keyword type is refused."""
    with pytest.raises(jsonschema.SchemaError):
        jsonschema.Draft202012Validator.check_schema({"type": "array", "minItems": "three"})


# ------------------------------------------------------------------ json_text: the files' text, fast
_scalar = st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats(allow_nan=False, allow_infinity=False) \
    | st.text(max_size=5)
# long lists of numbers (what json_text writes itself) made by repeating a short draw; some with a bool or a string
_numbers = st.lists(st.floats(allow_nan=False, allow_infinity=False) | st.integers(-(2**70), 2**70), min_size=1, max_size=4)
_long = st.tuples(_numbers, st.integers(200, 300), st.sampled_from([None, True, "x", None])).map(
    lambda t: ((t[0] * 300)[:t[1]] + ([] if t[2] is None else [t[2]])))
_json = st.recursive(_scalar | _long, lambda kids: st.lists(kids, max_size=3) | st.dictionaries(st.text(max_size=4), kids,
                                                                                                 max_size=3), max_leaves=8)


@given(_json)
def test_json_text_is_json_dumps_byte_for_byte(obj):
    """json_text writes the long lists of numbers itself (the 10^6 weights of a model file took ~2.4 s
    in json's pure-Python indented encoder); its text must be json.dumps(indent=1)'s, at any depth."""
    assert json_text(obj) == json.dumps(obj, indent=1, allow_nan=False) + "\n"


@pytest.mark.parametrize("bad, where", [({"w": {"z": [0.5] * 300 + [float("nan")]}}, "w.z[300]"),
                                        ({"fit": {"sigma": float("inf")}}, "fit.sigma"),
                                        ({"a": [1.0, [2.0, float("-inf")]]}, "a[1][1]")])
def test_json_text_refuses_a_number_json_cannot_hold(bad, where):
    with pytest.raises(InputError, match=re.escape(where) + r" is .*not a finite number"):
        json_text(bad)
