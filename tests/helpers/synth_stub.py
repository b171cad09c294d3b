"""A stand-in for :func:`pwas_hdl.flow.synthesis.synthesize` for the tests of explore's measured mode."""

from __future__ import annotations

import json
from pathlib import Path


def stub_synthesis(monkeypatch) -> list[tuple[str, str, dict]]:
    """Replace ``synthesize`` by a stub (no tools needed) for the test; returns the list it appends
    ``(folder name, target, manifest)`` to for every design it is given. The stub's resources: LUTs
    100 + the weight width, 50 FFs, 3 DSPs, 3 BRAMs, and the manifest's memory bits."""
    import pwas_hdl.flow.synthesis as synthesis

    built: list[tuple[str, str, dict]] = []

    def fake(outdir: Path, target: str, **kw) -> dict:
        man = json.loads((Path(outdir) / "manifest.json").read_text())
        built.append((Path(outdir).name, target, man))
        return {"luts": 100 + man["arithmetic"]["weight_width"], "ffs": 50, "dsp": 3, "bram": 3,
                "memory_bits": man["memory"]["bits"]}

    monkeypatch.setattr(synthesis, "synthesize", fake)
    return built
