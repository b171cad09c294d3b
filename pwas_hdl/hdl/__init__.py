"""RTL generator: the pipelined PWAS core and the virtual-sensor top as Amaranth components,
and their Verilog export.

Typical use::

    from pwas_hdl.bittrue import FixedPointModel
    from pwas_hdl.hdl import build_core, emit_verilog, design_info

    model = FixedPointModel.from_sensor(sensor)
    core = build_core(model, memory="banked", pipeline="balanced", name="pwas_core")
    text = emit_verilog(core)               # one Verilog-2005 module named "pwas_core"
    info = design_info(core)                # latency, II, ports, payload fields, memory
"""

from .core import PWASCore, core_input_layout, core_output_layout
from .emit import emit_verilog, memory_hex_files, normalise_verilog, port_list
from .params import PIPELINE_PRESETS, CoreParams, MemoryPlan, Pipeline, reference_eval
from .api import build_core, build_sensor, design_info
from .sensor_top import PWASSensorTop, lag_plan

__all__ = [
    "PWASCore",
    "CoreParams",
    "MemoryPlan",
    "Pipeline",
    "PIPELINE_PRESETS",
    "reference_eval",
    "core_input_layout",
    "core_output_layout",
    "build_core",
    "build_sensor",
    "PWASSensorTop",
    "lag_plan",
    "design_info",
    "emit_verilog",
    "memory_hex_files",
    "normalise_verilog",
    "port_list",
]
