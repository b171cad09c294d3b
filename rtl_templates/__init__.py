"""RTL, FuseSoC, Yosys and report templates; shipped as pwas_hdl.rtl_templates."""
