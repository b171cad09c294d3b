"""Benchmark scripts (run as python benchmarks/NAME.py, or through pwas-hdl bench); shipped as pwas_hdl.benchmarks."""
