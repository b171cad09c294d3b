"""``CliRunner``: typer's test runner on the Click command that :func:`pwas_hdl.cli.command` builds
once per process (typer's own runner rebuilds the whole command tree, ~50 ms, on every ``invoke``).
Use it exactly as ``typer.testing.CliRunner``: ``CliRunner().invoke(app, [...])``."""

from __future__ import annotations

from unittest import mock

import typer.main
import typer.testing

import pwas_hdl.cli


def _command(app):
    return pwas_hdl.cli.command() if app is pwas_hdl.cli.app else typer.main.get_command(app)


class CliRunner(typer.testing.CliRunner):
    """:class:`typer.testing.CliRunner` that reuses pwas-hdl's built Click command."""

    def invoke(self, app, args=None, **kwargs):  # noqa: D102 - as typer's
        with mock.patch.object(typer.testing, "_get_command", _command):
            return super().invoke(app, args, **kwargs)


def assert_refused(res, *fragments: str) -> str:
    """A refused command: exit 2, no exception but the exit, exactly one line starting with
    ``error:``, no traceback, each of ``fragments`` in that line (returned)."""
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("error:")]
    assert len(errors) == 1, res.output
    assert "Traceback" not in res.output
    for frag in fragments:
        assert frag in errors[0], (frag, errors[0])
    return errors[0]
