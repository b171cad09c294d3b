"""The scheduler address: a value from $PWAS_HDL_SCHEDULER is named as the variable (not --scheduler),
and a port out of 1..65535 is refused at once instead of after the 20 s connect timeout (D17)."""

from __future__ import annotations

import time

import pytest
from helpers.cli import CliRunner

import pwas_hdl.cli as cli
from pwas_hdl.errors import InputError
from pwas_hdl.flow.executor import Executor

RUNNER = CliRunner()


def test_a_bad_address_from_the_environment_names_the_variable(monkeypatch):
    monkeypatch.setenv("PWAS_HDL_SCHEDULER", "foo")
    with pytest.raises(InputError) as exc:
        Executor()
    assert "environment variable PWAS_HDL_SCHEDULER" in str(exc.value) and "--scheduler" not in str(exc.value)
    assert "unset PWAS_HDL_SCHEDULER" in str(exc.value)


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:99999", "tcp://127.0.0.1:0", "tcp://host:http"])
def test_a_port_out_of_range_is_refused_at_once(tmp_path, monkeypatch, address):
    monkeypatch.chdir(tmp_path)
    t0 = time.monotonic()
    res = RUNNER.invoke(cli.app, ["bench", "battery", "--quick", "-o", "b.json", "--scheduler", address])
    lines = res.output.strip().splitlines()
    assert res.exit_code == 2 and len(lines) == 1, res.output
    assert lines[0].startswith("error: --scheduler") and "1 to 65535" in lines[0], lines[0]
    assert time.monotonic() - t0 < 10 and not any(tmp_path.iterdir())


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:8786", "tcp://[::1]:8786", "tcp://host", "inproc://x"])
def test_good_addresses_pass_the_check(address):
    assert Executor(scheduler=address).scheduler == address  # no connection before the executor is entered
