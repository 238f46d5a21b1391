"""Every command's --help is plain text: no reStructuredText markup (``literal``, :func:`x`) leaks from
the docstrings that click prints, and every help ends its examples in runnable lines."""

from __future__ import annotations

import re

import click
import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main as psg_data
from psg_data.cli.psg_eval_cmd import main as psg_eval

RST = re.compile(r"``|:(func|class|meth|mod|attr|data|ref|doc):`|\.\. [a-z]+::|\*\*\w")


def _commands() -> list[tuple[str, click.Command, list[str]]]:
    out: list[tuple[str, click.Command, list[str]]] = [("psg-data", psg_data, []), ("psg-eval", psg_eval, [])]
    for prog, group in (("psg-data", psg_data), ("psg-eval", psg_eval)):
        assert isinstance(group, click.Group)
        ctx = click.Context(group)
        out += [(prog, group, [name]) for name in group.list_commands(ctx)]
    return out


@pytest.mark.parametrize(("prog", "group", "args"), _commands(), ids=lambda v: v if isinstance(v, str) else
                         " ".join(v) if isinstance(v, list) else "")
def test_help_has_no_rst_markup(prog: str, group: click.Command, args: list[str]) -> None:
    group = psg_data if prog == "psg-data" else psg_eval
    r = CliRunner().invoke(group, [*args, "--help"], terminal_width=100)
    assert r.exit_code == 0, r.output
    hits = [ln for ln in r.stdout.splitlines() if RST.search(ln) or "\b" in ln]
    assert not hits, f"{prog} {' '.join(args)} --help shows markup: {hits}"
