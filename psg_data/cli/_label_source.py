"""``--labels SOURCE``: the label source's syntax checked by click (a malformed one is a usage error, exit 2)."""

from __future__ import annotations

from typing import Any

import click

__all__ = ["LabelSourceType"]


class LabelSourceType(click.ParamType):
    """A click type for a label source (:func:`psg_data.labeling.parse_source`); the value stays the string."""

    name = "source"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        """``value`` unchanged when it is a label source's syntax."""
        if value in ("gt", "privileged", "observed"):  # the common cases, without importing the labeling package
            return str(value)
        from psg_data.errors import PsgDataError
        from psg_data.labeling import parse_source

        try:
            parse_source(str(value))
        except PsgDataError as exc:
            self.fail(str(exc)[:200], param, ctx)
        return str(value)
