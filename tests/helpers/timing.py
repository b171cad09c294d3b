"""A stand-in for the timing closure's place and route (``pwas_hdl.flow.timing_closure.measure_design``)."""

from __future__ import annotations


class FakePlaceAndRoute:
    """Stands for `measure_design`: fmax grows with the design's latency (so deeper candidates pass);
    records the latency of every design it was given."""

    def __init__(self, mhz_per_cycle: float):
        self.mhz_per_cycle = mhz_per_cycle
        self.built: list[tuple[dict, int]] = []

    def __call__(self, gd, fpga, *, freq_mhz, seed=1, device=None, workdir, harness=True, progress=None):
        lat = gd.manifest["latency_cycles"]
        self.built.append((gd.manifest["pipeline"], lat))
        fm = self.mhz_per_cycle * lat
        return {"fmax_mhz": fm, "latency_ns": lat * 1000.0 / fm, "luts": 1, "ffs": 1, "ffs_core": 1, "dsp": 0, "bram": 0,
                "critical_path": None, "device": "45k", "part": "LFE5U-45F-6CABGA381", "tools": {"fake": "1"}}
