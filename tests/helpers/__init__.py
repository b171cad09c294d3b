"""Test helpers imported by test files (not test files themselves): hand-built models and stimulus
of the HDL tests (hdl_models), the independent integer oracle of the core (hdl_reference)."""
