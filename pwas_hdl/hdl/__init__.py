"""RTL generator: the pipelined PWAS core and the virtual-sensor top as Amaranth components,
and their Verilog export.

Typical use::

    from pwas_hdl.fixedpoint.bittrue import FixedPointModel
    from pwas_hdl.hdl import build_core, build_sensor, emit_verilog, design_info

    model = FixedPointModel.from_sensor(sensor)
    core = build_core(model, memory="banked", pipeline="balanced", name="pwas_core")
    text = emit_verilog(core)          # one Verilog-2005 module "pwas_core" (memory_init="readmemh"
                                       # for $readmemh files, see memory_hex_files)
    info = design_info(core)           # latency, II, ports, payload fields, memory, pipeline
    top = build_sensor(model, sensor.lags_, name="pwas_sensor")   # lag bank + core

Verilog ports, in module order, as ``emit_verilog(..., ports="amaranth")`` names them (the
flattened ``amaranth.lib.stream`` members); the default ``ports="axis"`` names them ``aclk``,
``aresetn`` (active **low**), ``s_axis_tvalid/tready/tdata``, ``m_axis_tvalid/tready/tdata``,
``warm`` (:func:`~pwas_hdl.hdl.emit.port_list`). All payloads are plain unsigned vectors, fields
LSB first as listed by ``design_info(...)["payload"]``:

=================  ======  ==========================================================
``clk``            in      rising edge
``rst``            in      synchronous, active high; clears the valid bits only
``in__valid``      in
``in__ready``      out     ``~out__valid | out__ready`` (sensor top: also 1 during warm-up)
``in__payload``    in      core: ``n`` signed ``B_in`` codes (``x_j`` at ``[j*B_in +: B_in]``);
                           sensor top: one code per signal (u0.., y0..)
``out__valid``     out
``out__ready``     in
``out__payload``   out     ``nz`` signed ``B_out`` codes (``z_i`` at ``[i*B_out +: B_out]``),
                           then ``out_of_range`` at bit ``nz*B_out``
``warm``           out     sensor top only: the lag bank holds ``M-1`` samples
=================  ======  ==========================================================

A classifier model (``classifier=`` of :func:`build_core` / :func:`build_sensor`, and of the warped
builders of :mod:`pwas_hdl.hdl.warp`) adds an
:class:`~pwas_hdl.hdl.argmax.ArgmaxStage` after the core: ``out__payload`` then ends with the class
index (``class_index``, ties to the lowest index) and the latency grows by
:func:`~pwas_hdl.hdl.argmax.argmax_latency`.

Latency (cycles from the input transfer to ``out__valid``, no stalls) is ``component.latency``
= ``Pipeline.latency(n)`` = split + rank + 1 (memory) + mem_out + product
+ ceil(ceil(log2(n+1)) / tree_levels) + 1 (output); II = 1. ``build_core(..., architecture="serial")``
(and ``build_sensor``) give :class:`SerialPWASCore` instead: one multiplier per target, II = n + 1
(:mod:`pwas_hdl.hdl.serial_core`). Non-uniform power-of-two partitions: :mod:`pwas_hdl.hdl.warp`.
"""

from pwas_hdl.hdl.core import PWASCore, core_input_layout, core_output_layout
from pwas_hdl.hdl.emit import emit_verilog, memory_hex_files, normalise_verilog, port_list
from pwas_hdl.hdl.params import PIPELINE_PRESETS, CoreParams, MemoryPlan, Pipeline
from pwas_hdl.hdl.api import build_core, build_sensor, design_info
from pwas_hdl.hdl.sensor_top import PWASSensorTop, lag_plan
from pwas_hdl.hdl.argmax import ArgmaxStage, argmax_latency
from pwas_hdl.hdl.serial_core import SerialPWASCore

__all__ = [
    "PWASCore",
    "CoreParams",
    "MemoryPlan",
    "Pipeline",
    "PIPELINE_PRESETS",
    "core_input_layout",
    "core_output_layout",
    "build_core",
    "build_sensor",
    "PWASSensorTop",
    "SerialPWASCore",
    "lag_plan",
    "ArgmaxStage",
    "argmax_latency",
    "design_info",
    "emit_verilog",
    "memory_hex_files",
    "normalise_verilog",
    "port_list",
]
