"""Shared CLI plumbing: the --quiet option, logging set-up and progress output (from
:mod:`psg_data.cli._progress`); the error contract (exit codes, one ``error:`` line) is in
:mod:`psg_data.cli._errors`.
"""

from __future__ import annotations

import click

from psg_data.cli._errors import EXIT_OK, EXIT_PROBLEMS, EXIT_USAGE, handle_errors
from psg_data.cli._progress import Progress, setup_logging

__all__ = ["handle_errors", "setup_logging", "Progress", "quiet_option", "EXIT_OK", "EXIT_PROBLEMS", "EXIT_USAGE"]


quiet_option = click.option("--quiet", "-q", is_flag=True, help="Only print warnings, errors and results.")
