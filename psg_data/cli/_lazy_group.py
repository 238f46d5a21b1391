"""A click group whose sub-commands are imported only when invoked (keeps start-up fast)."""

from __future__ import annotations

import importlib
from typing import Any

import click

from psg_data.cli._errors import ContractGroup

__all__ = ["LazyGroup"]


class LazyGroup(ContractGroup):
    """``lazy_commands`` maps a command name to ``"module:attribute"`` (errors as one line, see ``_errors``)."""

    def __init__(self, *args: Any, lazy_commands: dict[str, str] | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.lazy_commands = dict(lazy_commands or {})

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(set(super().list_commands(ctx)) | set(self.lazy_commands))

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in self.lazy_commands:
            module, attr = self.lazy_commands[cmd_name].split(":")
            cmd = getattr(importlib.import_module(module), attr)
            if not isinstance(cmd, click.Command):  # pragma: no cover
                raise TypeError(f"{self.lazy_commands[cmd_name]} is not a click command")
            return cmd
        return super().get_command(ctx, cmd_name)
