"""The hardware manifest contract (pwas_hdl.design.manifest, schemas/manifest-v2.schema.json)."""

from __future__ import annotations

import copy
import json

import jsonschema
import pytest

from pwas_hdl.design.generate import build_design, write_folder
from pwas_hdl.design.manifest import (
    MANIFEST_FORMAT, MANIFEST_SCHEMA_ID, MANIFEST_VERSION, load_manifest, manifest_errors, manifest_text,
    validate_manifest,
)
from pwas_hdl.errors import InputError
from pwas_hdl.resources import schemas_dir
from pwas_hdl.verify.simulation import sim_module

synthetic_model = sim_module("pwas_designs").synthetic_model  # the RTL tests' model factory (shipped in sim/)


@pytest.fixture(scope="module")
def manifests() -> dict[str, dict]:
    m = synthetic_model(1, 2, 1, 1, 2, nz=2, seed=4)
    return {d: build_design(m, design=d).manifest for d in ("core", "sensor")}


@pytest.mark.parametrize("design", ["core", "sensor"])
def test_generated_manifest_validates_with_jsonschema_itself(manifests, design):
    man = manifests[design]
    schema = json.loads((schemas_dir() / "manifest-v2.schema.json").read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(man)
    assert (man["$schema"], man["format"], man["version"]) == (MANIFEST_SCHEMA_ID, MANIFEST_FORMAT, MANIFEST_VERSION)
    assert schema["$id"] == MANIFEST_SCHEMA_ID and MANIFEST_VERSION == 2
    assert manifest_errors(man) == []
    validate_manifest(man)
    assert ("warmup" in man["lags"]) == (design == "sensor")


def test_written_folder_loads_and_text_round_trips(manifests, tmp_path):
    m = synthetic_model(0, 2, 0, 1, 3, seed=1)
    gd = build_design(m, design="core")
    out = write_folder(gd.files, tmp_path / "hw")
    text = (out / "manifest.json").read_text(encoding="utf-8")
    assert text == manifest_text(gd.manifest)
    assert load_manifest(out) == gd.manifest == load_manifest(out / "manifest.json")


def _set(d, path, value):
    d = copy.deepcopy(d)
    node = d
    for k in path[:-1]:
        node = node[k]
    if value is _DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return d


_DELETE = object()


@pytest.mark.parametrize(
    "path, value, message",
    [
        (("latency_cycles",), 2.5, "latency_cycles must be an integer, got 2.5"),
        (("ii",), 0, "ii must be >= 1, got 0"),
        (("top",), "1top", "top must match"),
        (("ports", 2, "width"), "12", 'ports[2].width must be an integer, got "12"'),
        (("ports", 0, "direction"), "inout", 'ports[0].direction must be one of "input", "output", got "inout"'),
        (("ports", 1, "colour"), "red", "ports[1] has the unknown key 'colour'"),
        (("memory", "kind"), _DELETE, "memory.kind is missing"),
        (("memory", "layout"), "banked", "memory has the unknown key 'layout'"),
        (("files", "verilog"), "../x.v", "files.verilog"),
        (("lags", "regressors"), [], "lags.regressors must have at least 1 item, got 0"),
        (("clock", "port"), "clock", "clock.port 'clock' is not one of the ports"),
        (("generator", "options", "design"), "sensor", "generator.options.design is 'sensor' but design is 'core'"),
        (("domain", "lo"), [0.0], "domain.lo has 1 values for 3 lags.regressors"),
        (("lags", "warmup"), {"samples_without_output": 1, "port": "warm", "meaning": "x"},
         "lags.warmup is given for a core design"),
    ],
)
def test_broken_manifest_one_message_naming_the_key(manifests, tmp_path, path, value, message):
    bad = _set(manifests["core"], path, value)
    (tmp_path / "manifest.json").write_text(json.dumps(bad))
    with pytest.raises(InputError) as ei:
        load_manifest(tmp_path)
    msg = str(ei.value)
    assert msg.startswith(f"{tmp_path / 'manifest.json'}: "), msg
    assert message in msg and "re-run `pwas-hdl generate`" in msg and "\n" not in msg, msg


def test_field_outside_its_port_and_overlapping(manifests):
    man = manifests["core"]
    i = next(k for k, p in enumerate(man["ports"]) if p["role"] == "out.payload")
    wide = _set(man, ("ports", i, "fields", 0, "width"), man["ports"][i]["width"] + 1)
    assert any("reaches bit" in e for e in manifest_errors(wide))
    lap = _set(man, ("ports", i, "fields", 1, "lsb"), 0)
    assert any("overlaps another field" in e for e in manifest_errors(lap))


def test_sensor_needs_its_warmup(manifests):
    bad = _set(manifests["sensor"], ("lags", "warmup"), _DELETE)
    with pytest.raises(InputError, match="lags.warmup is missing"):
        validate_manifest(bad, "m")


def test_version_1_is_refused_with_the_fix(manifests, tmp_path):
    old = {k: v for k, v in manifests["core"].items() if k != "$schema"} | {"version": 1}
    (tmp_path / "manifest.json").write_text(json.dumps(old))
    with pytest.raises(InputError, match=r"pwas-hdl-manifest version 1 is not supported \(this pwas-hdl reads version 2\); "
                                         r"re-run `pwas-hdl generate`"):
        load_manifest(tmp_path)


def test_not_json_or_missing(tmp_path):
    with pytest.raises(FileNotFoundError, match="pwas-hdl generate"):
        load_manifest(tmp_path)
    (tmp_path / "manifest.json").write_text('{"format": "pwas-hdl-manifest", "version": 2, "latency_cycles": NaN}')
    with pytest.raises(InputError, match="NaN is not a JSON number"):
        load_manifest(tmp_path)
    (tmp_path / "manifest.json").write_text("[]")
    with pytest.raises(InputError, match='is not a pwas-hdl-manifest file'):
        load_manifest(tmp_path)


def test_cli_reports_the_bad_key(manifests, tmp_path, capsys):
    from pwas_hdl.cli import main

    m = synthetic_model(0, 2, 0, 1, 3, seed=1)
    out = write_folder(build_design(m).files, tmp_path / "hw")
    man = json.loads((out / "manifest.json").read_text())
    man["ports"][0]["width"] = -1
    (out / "manifest.json").write_text(json.dumps(man))
    assert main(["report", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "ports[0].width must be >= 1, got -1" in err[0]
