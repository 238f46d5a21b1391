"""``psg-data``: build, convert, check, inspect and label psg-datasets.

Exit codes: 0 success; 1 invalid input or problems found (one ``error: ...`` line each); 2 bad
command line.
"""

from __future__ import annotations

import click

from psg_data import __version__
from psg_data.cli._lazy_group import LazyGroup

__all__ = ["main"]

_COMMANDS = {
    "validate": "psg_data.cli._inspect_cmds:validate_cmd",
    "info": "psg_data.cli._inspect_cmds:info_cmd",
    "synth": "psg_data.cli._synth_cmd:synth_cmd",
    "convert": "psg_data.cli._convert_cmd:convert_cmd",
    "label": "psg_data.cli._label_cmd:label_cmd",
    "view": "psg_data.cli._view_cmd:view_cmd",
    "lab-stats": "psg_data.cli._lab_stats_cmd:lab_stats_cmd",
    "graph": "psg_data.cli._graph_cmd:graph_cmd",
}


@click.group(cls=LazyGroup, lazy_commands=_COMMANDS, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="psg-data")
def main() -> None:
    """Build, convert, validate, inspect and label psg-datasets.

    \b
    Examples:
      psg-data synth /tmp/lab            # the built-in synthetic lab (84 scans)
      psg-data validate /tmp/lab         # OK, or one line per problem and exit 1
      psg-data info /tmp/lab             # summary: scans, frames, rooms, receptacles, ...
      psg-data view /tmp/lab --save lab.rrd   # a Rerun recording (psg-data[viewer])
    """
