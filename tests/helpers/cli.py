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
