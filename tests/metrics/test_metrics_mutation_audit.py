"""Tests written by the audit of bench/mutation_equivalent.txt (docs/TESTING.md, "Audit of the
equivalents"): inputs that tell apart mutants that were listed as equivalent.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from psg_data.metrics import distance_travelled


@pytest.mark.parametrize("distances", [[1 + 2j, 3 + 0j], [2.0, 1j]])
def test_distance_travelled_refuses_complex_distances_as_float64_conversion_does(distances: list[complex]) -> None:
    """Python complex numbers are no distances: numpy's float64 conversion refuses them (the
    reference), and so does distance_travelled, rather than dropping the imaginary parts.
    """
    with pytest.raises(TypeError):
        np.asarray(distances, dtype=np.float64)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a ComplexWarning would mean the imaginary part was dropped
        with pytest.raises(TypeError):
            distance_travelled(distances)
