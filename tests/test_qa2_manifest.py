"""Hand-edited manifests are cross-checked (pwas_hdl.design.manifest): the lag structure against the
regressors, files.hex against memory and the files on disk, field widths against their formats,
latency against the pipeline, file names inside the folder. Every reader refuses them: one error:
line, exit 2, nothing written."""

from __future__ import annotations

import copy
import json
import shutil

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pwas_hdl.design.generate import build_design, write_folder
from pwas_hdl.design.manifest import load_manifest, manifest_errors
from pwas_hdl.errors import InputError
from pwas_hdl.verify.simulation import sim_module
from tests.helpers.cli import CliRunner
from tests.helpers.folders import tree

synthetic_model = sim_module("pwas_designs").synthetic_model


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """A tiny lag-bank sensor (Mu = 1, My = 2, p = 1) whose Verilog reads its hex files."""
    root = tmp_path_factory.mktemp("qa2man")
    m = synthetic_model(1, 2, 1, 1, 1, nz=2, seed=4)
    return {"sensor": write_folder(build_design(m, design="sensor", memory_init="readmemh").files, root / "sensor")}


def _copy(folders, kind, tmp_path):
    out = tmp_path / kind
    shutil.copytree(folders[kind], out)
    return out, json.loads((out / "manifest.json").read_text())


def _edit(man, path, value):
    man = copy.deepcopy(man)
    node = man
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return man


def _out_index(man):
    return next(i for i, p in enumerate(man["ports"]) if p["role"] == "out.payload")


@pytest.mark.parametrize("path, value, message", [
    (("lags", "My"), 3, "lags Mu = 1, My = 3 with 1 inputs and 1 outputs need 4 regressors, lags.regressors has 3"),
    (("lags", "My"), 10**9, "lags Mu = 1, My = 1000000000 with 1 inputs and 1 outputs need 1000000001 regressors"),
    (("lags", "Mu"), 0, "lags.regressors has 3 names, lags Mu = 0, My = 2 give 2"),
    (("lags", "regressors", 1), "y0[t-2]", "are not the regressors"),
    (("lags", "outputs"), ["y9"], "are not the regressors"),
    (("lags", "warmup", "samples_without_output"), 4, "fills after 1 samples"),
    (("formats", "inputs", 0, "name"), "u0[t-1]", "formats.inputs[0].name 'u0[t-1]' differs from lags.regressors[0]"),
    (("files", "hex", 0, "depth"), 100, "files.hex[0] (pwas_sensor_rom_b0.hex) has depth 100 and width 20, memory has depth 4"),
    (("files", "hex", 1, "width"), 64, "has depth 4 and width 64"),
    (("files", "hex", 0, "fields", 1, "lsb"), 5, "overlaps another field"),
    (("files", "hex", 0, "fields", 0, "target"), "zz", "files.hex[0].fields[0].target 'zz' is not one of lags.targets"),
    (("memory", "words"), 10, "memory.words 10 is not memories x depth"),
    (("latency_cycles",), 9, "latency_cycles is 9, the pipeline"),
    (("ii",), 2, "ii is 2, architecture (parallel) gives ii 1"),
    (("files", "model"), "..", "files.model"),
    # the testbenches drive the ports by name: a renamed one failed inside the simulator ("the testbench
    # wrote no result"), it is compared with the Verilog module's header
    (("ports", 2, "name"), "x", "ports names x, which module pwas_sensor in pwas_sensor.v does not have (its ports: aclk,"),
])
def test_inconsistent_sensor_manifest_is_refused(folders, tmp_path, path, value, message):
    out, man = _copy(folders, "sensor", tmp_path)
    (out / "manifest.json").write_text(json.dumps(_edit(man, path, value)))
    with pytest.raises(InputError) as ei:
        load_manifest(out)
    assert message in str(ei.value) and "\n" not in str(ei.value), str(ei.value)


def test_field_widths_follow_their_formats(folders, tmp_path):
    _, man = _copy(folders, "sensor", tmp_path)
    i = _out_index(man)
    w = man["ports"][i]["fields"][0]["width"]
    bad = _edit(man, ("ports", i, "fields", 0, "format", "bits"), w + 2)
    assert any("its format" in e for e in manifest_errors(bad)), manifest_errors(bad)
    bad = _edit(man, ("formats", "output", "frac"), man["formats"]["output"]["frac"] + 1)
    assert any("formats.output is" in e for e in manifest_errors(bad)), manifest_errors(bad)
    j = next(k for k, p in enumerate(man["ports"]) if p["role"] == "in.payload")
    bad = _edit(man, ("ports", j, "fields", 0, "domain_codes"), [-5000, 5000])
    assert any("domain_codes" in e for e in manifest_errors(bad)), manifest_errors(bad)
    assert manifest_errors(man) == []


def test_hex_files_on_disk_match_their_depth_and_width(folders, tmp_path):
    out, man = _copy(folders, "sensor", tmp_path)
    h = man["files"]["hex"][0]["file"]
    good = (out / h).read_text()
    (out / h).write_text("".join(good.splitlines(keepends=True)[:-1]))  # one word short
    with pytest.raises(InputError, match=rf"{h} has {man['files']['hex'][0]['depth'] - 1} words, files.hex\[0\].depth is"):
        load_manifest(out)
    (out / h).write_text("fffffffff\n" + "".join(good.splitlines(keepends=True)[1:]))  # 36 bits in a 20-bit word
    with pytest.raises(InputError, match=r"line 1 of .* is not a 20-bit hex word"):
        load_manifest(out)
    # a comment on top (one line more than depth): the line is named, not the word count; blank lines
    # count in the line number as an editor shows it
    (out / h).write_text("\n// weights\n" + good)
    with pytest.raises(InputError, match=r"line 2 of .* \('// weights'\) is not a 20-bit hex word; the file holds one word a line"):
        load_manifest(out)
    (out / h).unlink()  # the Verilog reads it with $readmemh
    with pytest.raises(InputError, match=r"is missing \(the Verilog reads it with \$readmemh\)"):
        load_manifest(out)


def test_a_listed_file_may_not_lead_outside_the_folder(folders, tmp_path):
    out, man = _copy(folders, "sensor", tmp_path)
    (tmp_path / "elsewhere.json").write_text((out / "model.json").read_text())
    (out / "model.json").unlink()
    (out / "model.json").symlink_to(tmp_path / "elsewhere.json")
    with pytest.raises(InputError, match="files: model.json leads outside the folder"):
        load_manifest(out)


@pytest.mark.parametrize("command", ["report", "export-testbench", "simulate", "synth"])
def test_every_reader_refuses_an_inconsistent_manifest(folders, tmp_path, command):
    import pwas_hdl.cli

    out, man = _copy(folders, "sensor", tmp_path)
    (out / "manifest.json").write_text(json.dumps(_edit(man, ("lags", "My"), 3)))
    (tmp_path / "data.csv").write_text("u0,y0,z0,z1\n" + "0,0,0,0\n" * 4)
    before = tree(tmp_path)
    args = {"report": ["report", str(out), "--json", str(tmp_path / "r.json")],
            "export-testbench": ["export-testbench", str(out), "-o", str(tmp_path / "tb")],
            "simulate": ["simulate", str(out), str(tmp_path / "data.csv"), "-o", str(tmp_path / "hw.csv")],
            "synth": ["synth", str(out), "--fpga", "generic", "-o", str(tmp_path / "syn")]}[command]
    res = CliRunner().invoke(pwas_hdl.cli.app, args)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and "need 4 regressors" in lines[0], res.output
    assert tree(tmp_path) == before



def _additive_memory(part_words=(6, 12, 60, 12)):
    parts = [{"memory": {"memories": mm, "depth": d, "words": w}}
             for mm, d, w in zip((2, 3, 4, 3), (3, 4, 15, 4), part_words)]
    return {"memory": {"memories": 12, "depth": 15, "words": 90, "n_vertices": 74, "word_bits": 20},
            "files": {"hex": []}, "formats": {"weight": {"bits": 10}}, "lags": {"targets": ["z"]},
            "additive": {"parts": parts}}


def test_additive_memory_is_checked_part_by_part():
    """An additive design's memory is its parts' (a-c-n4-z2-max-trunc: 12 memories, largest depth 15, 90
    words): the plain rule words = memories x depth refused every additive design whose parts differ in
    depth (generate raised InternalError on its own manifest)."""
    from pwas_hdl.design.manifest import _memory_errors

    assert _memory_errors(_additive_memory()) == []
    bad = _additive_memory((6, 12, 61, 12))
    errs = _memory_errors(bad)
    assert any("additive.parts[2].memory.words 61 is not memories x depth = 4 x 15" in e for e in errs)
    assert any("not the sum of the additive parts" in e for e in errs)


@given(st.integers(1, 70), st.lists(st.text("0123456789abcdefABCDEFg x", min_size=1, max_size=20).map(str.strip)
                                      .filter(bool), max_size=8))
def test_hex_word_pattern_is_the_per_line_rule(width, lines):
    """The folder check reads every hex file with one regular expression (a 10^6-word design spent
    ~2.5 s in a loop a line); it must accept exactly the lines the per-line rule accepts: at most
    ceil(width / 4) hex digits and a value below 2**width."""
    from pwas_hdl.design.manifest import _hex_words

    digits = -(-width // 4)
    rule = all(len(ln) <= digits and all(c in "0123456789abcdefABCDEF" for c in ln) and not int(ln, 16) >> width for ln in lines)
    assert (_hex_words(width).fullmatch("\n".join(lines) + "\n" if lines else "") is not None) == rule
    # the edge words themselves
    assert _hex_words(width).fullmatch(format((1 << width) - 1, f"0{digits}x") + "\n")
    assert not _hex_words(width).fullmatch(format(1 << width, "x") + "\n")
