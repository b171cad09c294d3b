"""The cocotb testbench and its runner; shipped as pwas_hdl.sim (loaded by path as top-level modules)."""
