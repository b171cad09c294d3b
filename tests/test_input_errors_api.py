"""Bad arguments to the public API raise :class:`~pwas_hdl.errors.InputError`, not a plain ``ValueError``.

InputError subclasses ValueError, so every test asserts the class InputError itself: each fails if
its site went back to ``raise ValueError(...)``. The messages are matched too, so that the test
exercises the intended check (and not another one that happens to refuse the same call).
"""

from __future__ import annotations

import types

import numpy as np
import pytest

from pwas_hdl.errors import InputError


def _grid(n: int = 1, p: int = 2):
    from pwas_hdl.fit.geometry import Grid

    return Grid([0.0] * n, [1.0] * n, p)


def _fixed_point_model(n: int = 2):
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel

    grid = _grid(n)
    return FixedPointModel(grid, np.linspace(-1.0, 1.0, grid.n_vertices), reference_error=0.01)


# ---------------------------------------------------------------- fit: grid, breakpoints, lags
def test_grid_lo_not_below_hi():
    from pwas_hdl.fit.geometry import Grid

    with pytest.raises(InputError, match=r"domain dimension 1 has zero or negative width \(\[2\.0, 2\.0\]\)"):
        Grid([0.0, 2.0], [1.0, 2.0], 2)
    with pytest.raises(InputError, match=r"domain dimension 0 has zero or negative width"):
        Grid([1.0], [0.0], 2)


def test_grid_partitions_and_breakpoints():
    from pwas_hdl.fit.geometry import Grid

    with pytest.raises(InputError, match=r"partitions\[0\]\) = 0, but every dimension needs p >= 1"):
        Grid([0.0], [1.0], 0)
    with pytest.raises(InputError, match=r"-p/--partitions \(partitions\) must be one integer or 2 integers"):
        Grid([0.0, 0.0], [1.0, 1.0], [2, 2, 2])
    with pytest.raises(InputError, match=r"breakpoints of dimension 0 must increase strictly"):
        Grid([0.0], [1.0], 2, breakpoints=[[0.0, 0.7, 0.5]])


def test_grid_evaluate_bad_points():
    grid = _grid(2)
    with pytest.raises(InputError, match=r"points have 3 coordinates but the grid has n = 2"):
        grid.evaluate(np.zeros(grid.n_vertices), np.zeros((1, 3)))
    with pytest.raises(InputError, match=r"weights have 2 rows but the grid has N = 9 vertices"):
        grid.evaluate(np.zeros(2), np.zeros((1, 2)))


def test_pow2_breakpoints_max_ratio():
    from pwas_hdl.fit.geometry import pow2_breakpoints

    x = np.linspace(0.0, 1.0, 50)[:, None]
    with pytest.raises(InputError, match=r"max_ratio must be a power of two >= 1, got 3"):
        pow2_breakpoints(x, [0.0], [1.0], 4, max_ratio=3)


def test_quantile_breakpoints_no_sample_inside():
    from pwas_hdl.fit.geometry import quantile_breakpoints

    with pytest.raises(InputError, match=r"no sample of dimension 0 lies inside its domain"):
        quantile_breakpoints(np.full((5, 1), 7.0), [0.0], [1.0], 2)


def test_lag_structure_negative_lag():
    from pwas_hdl.fit.regressors import LagStructure

    with pytest.raises(InputError, match=r"mu must be a non-negative integer, got -1"):
        LagStructure(-1, 1, 1, 1)
    with pytest.raises(InputError, match=r"the regressor is empty"):
        LagStructure(0, 0, 1, 1)


def test_tikhonov_order():
    from pwas_hdl.fit.regularized_lsq import tikhonov_matrix

    with pytest.raises(InputError, match=r"Tikhonov order must be 0 or 1, got 2"):
        tikhonov_matrix(_grid(), 2)


def test_additive_grid_parts():
    from pwas_hdl.fit.additive import AdditiveGrid

    with pytest.raises(InputError, match=r"part 0 \(1, 0\) must be sorted distinct indices in 0\.\.1"):
        AdditiveGrid([0.0, 0.0], [1.0, 1.0], 2, [[1, 0]])


def test_run_recurrence_initial_states():
    from pwas_hdl.fit.recurrent import run_recurrence

    with pytest.raises(InputError, match=r"1 initial states for 2 trajectories; give one initial state per trajectory"):
        run_recurrence(lambda io, zpast: io, [np.zeros((3, 1)), np.zeros((3, 1))], [np.zeros((1, 1))])


# ---------------------------------------------------------------- fixed point
def test_fixed_format_negative_width():
    from pwas_hdl.fixedpoint.formats import FixedFormat

    with pytest.raises(InputError, match=r"bits = -3: a fixed-point format needs at least 1 bit"):
        FixedFormat(-3, 0)
    with pytest.raises(InputError, match=r"overflow must be one of"):
        FixedFormat(8, 0, overflow="wrap-around")
    with pytest.raises(InputError, match=r"cannot parse fixed-point format 'q8'"):
        FixedFormat.from_string("q8")


def test_fixed_format_quantize_overflow_and_nan():
    from pwas_hdl.fixedpoint.formats import FixedFormat

    fmt = FixedFormat(4, 0, overflow="error")
    with pytest.raises(InputError, match=r"does not fit the fixed-point format"):
        fmt.quantize([100.0])
    with pytest.raises(InputError, match=r"at index \(1,\) is NaN"):
        fmt.quantize([1.0, float("nan")])


def test_shift_round_and_input_interval():
    from pwas_hdl.fixedpoint.formats import InputFormat, shift_round

    with pytest.raises(InputError, match=r"shift must be an integer >= 0, got -1"):
        shift_round(np.array([4]), -1)
    with pytest.raises(InputError, match=r"input domain \[1\.0, 1\.0\] must be finite with hi > lo"):
        InputFormat.for_interval(1.0, 1.0, 2)
    with pytest.raises(InputError, match=r"B_in too small for p = 4096 intervals"):
        InputFormat.for_interval(0.0, 1.0, 4096, bits=8)


def test_make_layout_kind():
    from pwas_hdl.fixedpoint.memory_layout import make_layout

    with pytest.raises(InputError, match=r"memory layout must be one of .*, got 'diagonal'"):
        make_layout(_grid(), "diagonal")


def test_layout_coordinates_outside_grid():
    from pwas_hdl.fixedpoint.memory_layout import make_layout

    layout = make_layout(_grid(2), "banked")
    with pytest.raises(InputError, match=r"vertex coordinates outside the grid: coordinate j must be in 0\.\.p_j"):
        layout.bank_addr_coords([[0, 5]])
    with pytest.raises(InputError, match=r"vertex index 9 is out of range \[0, 9\)"):
        layout.bank_addr(np.array([9]))


def test_readmemh_word_width():
    from pwas_hdl.fixedpoint.memory_layout import readmemh_text

    with pytest.raises(InputError, match=r"word width must be an integer >= 1, got 0"):
        readmemh_text([1, 2], 0)


def test_fixed_point_model_options():
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel

    grid = _grid()
    with pytest.raises(InputError, match=r"--overflow \(overflow\) must be one of error, saturate, got 'wrap'"):
        FixedPointModel(grid, np.zeros(grid.n_vertices), overflow="wrap")
    with pytest.raises(InputError, match=r"weights must have shape \(N, nz\) with N = 3"):
        FixedPointModel(grid, np.zeros(5))
    with pytest.raises(InputError, match=r"weights contain NaN or infinite values"):
        FixedPointModel(grid, np.array([0.0, np.inf, 1.0]))


def test_fixed_point_model_bad_inputs():
    fxm = _fixed_point_model(2)
    with pytest.raises(InputError, match=r"inputs have 3 columns, the model has n = 2"):
        fxm.quantize_inputs(np.zeros((1, 3)))
    with pytest.raises(InputError, match=r"input codes must be integers"):
        fxm.evaluate(np.full((1, 2), 0.5))


def test_reduction_of_nothing():
    from pwas_hdl.fixedpoint.reduction import tree_depth, tree_levels

    with pytest.raises(InputError, match=r"a reduction needs at least one item, got 0"):
        tree_depth(0)
    with pytest.raises(InputError, match=r"a reduction needs at least one item"):
        tree_levels([], lambda a, b, _lvl, _i: a + b)


# ---------------------------------------------------------------- hdl
def test_lag_plan_mismatch():
    from pwas_hdl.fit.regressors import LagStructure
    from pwas_hdl.hdl import lag_plan

    fxm = _fixed_point_model(2)
    with pytest.raises(InputError, match=r"the lag structure has n = 1 regressors, the model 2"):
        lag_plan(fxm, LagStructure(1, 0, 1, 0))
    with pytest.raises(InputError, match=r"does not match the model's regressor signals; pass the LagStructure"):
        lag_plan(fxm, LagStructure(2, 0, 1, 0))  # the model's regressors are x0, x1 (lag 0 each), not u0 lags 0, 1
    with pytest.raises(InputError, match=r"the model has no regressor_signals"):
        lag_plan(types.SimpleNamespace(n=1, regressor_signals=[]))


def test_pipeline_options():
    from pwas_hdl.hdl.params import Pipeline, goal_preset

    with pytest.raises(InputError, match=r"unknown pipeline preset 'fastest'"):
        Pipeline.cast("fastest")
    with pytest.raises(InputError, match=r"unknown pipeline option\(s\) \['turbo'\]"):
        Pipeline.cast({"turbo": True})
    with pytest.raises(InputError, match=r"counter_sum needs flat_sum"):
        Pipeline(counter_sum=True)
    with pytest.raises(InputError, match=r"unknown goal 'speed'"):
        goal_preset("speed")


def test_core_params_weights_do_not_fit():
    from pwas_hdl.hdl.params import CoreParams

    p = CoreParams.from_model(_fixed_point_model(1))
    bad = {k: getattr(p, k) for k in p.__dataclass_fields__}
    bad["weights"] = np.full((p.n_vertices, 1), 1 << (p.weight_width - 1))
    with pytest.raises(InputError, match=r"do not fit signed \d+ bits"):
        CoreParams(**bad)


def test_argmax_stage_select():
    from pwas_hdl.hdl import ArgmaxStage

    with pytest.raises(InputError, match=r"select must be one of .*, got 'median'"):
        ArgmaxStage(3, 8, select="median")


def test_build_core_module_name_and_architecture():
    from pwas_hdl.hdl import build_core

    fxm = _fixed_point_model(1)
    with pytest.raises(InputError, match=r"module name '1core' is not a Verilog identifier"):
        build_core(fxm, name="1core")
    with pytest.raises(InputError, match=r"module name 'wire' is a Verilog/SystemVerilog keyword"):  # hdl had its own
        build_core(fxm, name="wire")  # identifier check, without the keywords that generate --name refuses
    with pytest.raises(InputError, match=r"--architecture \(architecture\) must be one of .*, got 'systolic'"):
        build_core(fxm, architecture="systolic")


# ---------------------------------------------------------------- flow, io, systems
def test_synthesis_device_checks():
    from pwas_hdl.flow.synthesis import check_device

    with pytest.raises(InputError, match=r"unknown synthesis target 'xilinx'"):
        check_device("xilinx", None)
    with pytest.raises(InputError, match=r"unknown iCE40 device 'foo'"):
        check_device("ice40", "foo")
    with pytest.raises(InputError, match=r"the generic target has no device"):
        check_device("generic", "45k")


def test_floorplan_and_timing_closure_options():
    from pwas_hdl.flow.floorplan import check_floorplan
    from pwas_hdl.flow.timing_closure import close_timing, pipeline_candidates

    with pytest.raises(InputError, match=r"--floorplan \(floorplan\) must be one of"):
        check_floorplan("diagonal")
    with pytest.raises(InputError, match=r"a PWAS core needs at least one input"):
        pipeline_candidates(0)
    with pytest.raises(InputError, match=r"--clock-mhz \(target_mhz\) must be a positive number of MHz, got -5"):
        close_timing(lambda pipe: None, 2, -5)


def test_pareto_front_nan():
    from pwas_hdl.flow.explore import pareto_front

    with pytest.raises(InputError, match=r"an objective is NaN"):
        pareto_front([(1.0, float("nan")), (2.0, 1.0)])


def test_format_csv_lengths():
    from pwas_hdl.io.csv_table import format_csv

    with pytest.raises(InputError, match=r"columns have different lengths \[2, 3\]"):
        format_csv({"a": [1, 2], "b": [1, 2, 3]})


def test_lorenz_samples():
    from pwas_hdl.systems.lorenz import lorenz

    with pytest.raises(InputError, match=r"n_samples must be >= 1, got 0"):
        lorenz(0)


# ---------------------------------------------------------------- the command line
def test_cli_converted_site_is_one_error_line(capsys, tmp_path):
    """A converted site reached from the command line: one ``error:`` line, exit status 2, no
    traceback; under ``-v`` the traceback names the class, InputError (a plain ValueError prints
    the same ``error:`` line, so the class is only visible there)."""
    from pwas_hdl.cli import main

    args = ["synth", str(tmp_path), "--fpga", "ice40", "--device", "foo"]
    code = main(args)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("error: unknown iCE40 device 'foo'"), err
    assert "Traceback" not in err and "this is a bug" not in err

    code = main(["-v", *args])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "pwas_hdl.errors.InputError: unknown iCE40 device 'foo'" in err
    assert err.strip().splitlines()[-1].startswith("error: unknown iCE40 device 'foo'")
