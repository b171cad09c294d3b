"""The hardware manifest: the machine-readable description of a generated design.

``pwas-hdl generate`` writes ``manifest.json`` next to the Verilog; the cocotb testbenches, the
``simulate`` and ``synth`` commands and any FPGA flow read it instead of hard-coding ports, widths,
formats or latency. Format ``pwas-hdl-manifest``, version 1::

    {
      "format": "pwas-hdl-manifest", "version": 1,
      "generator": {"pwas_hdl": "0.1.0", "amaranth": "0.5.10"},
      "design": "core" | "sensor",              # PWAS core alone, or lag bank + core
      "top": "pwas_core",                        # Verilog module name
      "files": {"verilog": "pwas_core.v", "model": "model.json", "report": "report.md",
                "hex": [{"target": "z", "bank": 0, "file": "pwas_core_z_bank0.hex", "depth": .., "width": ..}],
                "templates": {...}},
      "clock": {"port": "clk", "edge": "rising"},
      "reset": {"port": "rst", "polarity": "high", "kind": "synchronous"},
      "latency_cycles": 7,                       # input transfer -> output valid, no stalls
      "ii": 1,                                   # initiation interval (samples per clock: 1/ii)
      "ports": [                                 # every top-level port of the Verilog module
        {"name": "in__payload", "direction": "input", "width": 48, "signed": false,
         "role": "in.payload",
         "fields": [{"name": "x0", "regressor": "y[t-3]", "lsb": 0, "width": 12, "signed": true,
                     "format": {FixedFormat.to_dict()}, "scale": .., "offset": ..}, ...]},
        {"name": "in__valid", ...}, {"name": "in__ready", ...}, {"name": "out__payload", ...}, ...
      ],
      "formats": {"inputs": [...], "weight": {...}, "output": {...}, "mu_frac": F},
      "domain": {"lo": [...], "hi": [...], "partitions": [...], "lo_code": [...], "frac_bits": [...]},
      "lags": {"Mu": .., "My": .., "inputs": [...], "outputs": [...], "targets": [...],
               "regressors": [...]},
      "error_bound": {"lsb": .., "physical": .., "terms": {...}},
      "memory": {"layout": "banked" | "replicated", "banks": n+1, "depth": .., "word_bits": ..,
                 "words": .., "bits": .., "n_vertices": N},
      "pipeline": {"preset": .., "stages": [...]}
    }

Physical value of a field: ``physical = offset + scale * code * 2**-frac`` (``format.frac``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

__all__ = ["MANIFEST_FORMAT", "MANIFEST_VERSION", "load_manifest", "port", "field"]

MANIFEST_FORMAT = "pwas-hdl-manifest"
MANIFEST_VERSION = 1


def load_manifest(outdir_or_file: str | os.PathLike) -> dict[str, Any]:
    """Read and check a manifest (a generated folder or the ``manifest.json`` itself).

    Raises
    ------
    FileNotFoundError
        No manifest there (run ``pwas-hdl generate`` first).
    ValueError
        Not a pwas-hdl manifest, another version, or not valid JSON.
    """
    p = Path(outdir_or_file)
    if p.is_dir():
        p = p / "manifest.json"
    if not p.exists():
        raise FileNotFoundError(f"{p} does not exist; run `pwas-hdl generate MODEL -o DIR` first")
    try:
        d = json.loads(p.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{p} is not valid JSON ({exc}); regenerate the design") from exc
    if not isinstance(d, dict) or d.get("format") != MANIFEST_FORMAT:
        raise ValueError(f"{p} is not a pwas-hdl manifest")
    if type(d.get("version")) is not int or d["version"] != MANIFEST_VERSION:
        raise ValueError(f"{p} has manifest version {d.get('version')!r}; this pwas-hdl reads {MANIFEST_VERSION}")
    return d


def port(manifest: dict[str, Any], role: str) -> dict[str, Any]:
    """The port whose ``role`` is ``role`` (e.g. ``"in.payload"``, ``"out.valid"``)."""
    for prt in manifest["ports"]:
        if prt.get("role") == role:
            return prt
    raise KeyError(f"the manifest has no port with role {role!r}")


def field(port_entry: dict[str, Any], name: str) -> dict[str, Any]:
    """A named bit field of a port."""
    for f in port_entry.get("fields", []):
        if f["name"] == name:
            return f
    raise KeyError(f"port {port_entry['name']} has no field {name!r}")
