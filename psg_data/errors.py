"""Exception hierarchy of psg-data.

Every error a user can cause by giving bad input derives from :class:`PsgDataError`. The command
line tools print such errors as one ``error: ...`` line and exit non-zero; any other exception is a
bug in psg-data and keeps its traceback.

Messages say what is wrong, where (file, row, field) and what was expected, for example::

    /data/lab/tables/frames.parquet:12: stamp_ns: must increase within a scan, got 5 after 7
"""

from __future__ import annotations

__all__ = [
    "PsgDataError",
    "FormatError",
    "ValidationError",
    "DatasetExistsError",
    "UnsafeOutputError",
    "ConversionError",
    "LabelingError",
    "EstimatorError",
    "NotFittedError",
    "EvaluationError",
    "GraphError",
    "NotOpenError",
]


class PsgDataError(Exception):
    """Root of every error psg-data raises for bad input or bad usage."""


class FormatError(PsgDataError, ValueError):
    """A dataset on disk does not follow the psg-dataset format (or is of a newer version)."""


class ValidationError(FormatError):
    """A dataset failed validation; ``problems`` holds every problem line found."""

    def __init__(self, problems: list[str]) -> None:
        """Keep every problem line; the first one becomes the message.

        Args:
            problems: the problem lines.
        """
        self.problems = list(problems)
        head = problems[0] if problems else "dataset is invalid"
        more = f" (and {len(problems) - 1} more problems)" if len(problems) > 1 else ""
        super().__init__(head + more)


class DatasetExistsError(PsgDataError, FileExistsError):
    """The output path exists and overwriting was not requested."""


class UnsafeOutputError(PsgDataError, ValueError):
    """Writing the output could destroy something psg-data did not write (an input, a foreign file)."""


class ConversionError(PsgDataError, ValueError):
    """A raw recording could not be converted into the canonical format."""


class LabelingError(PsgDataError, ValueError):
    """Labels or detections are inconsistent with the dataset."""


class EstimatorError(PsgDataError, ValueError):
    """An estimator was misconfigured, misused or returned invalid predictions."""


class NotFittedError(EstimatorError, AttributeError):
    """An estimator was used before ``fit`` (scikit-learn's contract)."""


class EvaluationError(PsgDataError, ValueError):
    """An evaluation could not run (empty split, missing labels, ...)."""


class GraphError(PsgDataError, ValueError):
    """A predictive graph was queried, updated or loaded with bad input (unknown object, bad time, bad file)."""


class NotOpenError(PsgDataError, RuntimeError):
    """A reader was used before ``open()`` (or after ``close()``)."""
