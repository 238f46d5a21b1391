"""The command-line entry points ``psg-data`` and ``psg-eval`` (click)."""
