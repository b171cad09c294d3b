"""The shipped JSON Schemas are valid schemas of their draft (pwas_hdl.io.json_contract does not
check them on every load: this test does, for every file in pwas_hdl/schemas/)."""

from __future__ import annotations

import json

import jsonschema
import pytest

from pwas_hdl.io.json_contract import load_schema
from pwas_hdl.resources import schemas_dir

SCHEMAS = sorted(p.name for p in schemas_dir().iterdir() if p.name.endswith(".schema.json"))


def test_every_format_has_a_schema():
    assert {"model-v2.schema.json", "manifest-v2.schema.json", "bench-results-v1.schema.json",
            "breakpoints-v1.schema.json", "estimator-v1.schema.json"} <= set(SCHEMAS)


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
