"""isf.compiled.arrays.copy_into, and isf's kernels compiled without numba's slice assignment."""

import numpy as np
import pytest

from isf.compiled.arrays import copy_into
from isf.warming import _kernels, warm_up


@pytest.mark.parametrize("shape", [(5,), (3, 4), (2, 3, 4), (2, 2, 3, 3)])
def test_copy_into_copies_as_numpy_assigns(shape):
    rng = np.random.default_rng(0)
    src = rng.normal(size=(3,) + shape)
    dst, expected = np.zeros((4,) + shape), np.zeros((4,) + shape)
    copy_into(dst[2], src[1])
    expected[2] = src[1]
    assert np.array_equal(dst, expected)


def test_copy_into_refuses_arrays_of_other_shapes():
    with pytest.raises(ValueError, match="differ in shape"):
        copy_into(np.zeros((2, 3)), np.zeros((3, 2)))


def test_no_kernel_links_numbas_shape_mismatch_message():
    """A slice assignment from an array links numba's ``raise_with_shape_context`` (its error
    message formats both shapes), which costs seconds of compiling per process
    (docs/design-decisions.md): no kernel of a warm-up links it (a kernel compiled here or
    loaded from the cache carries the code of every kernel it calls)."""
    warm_up()
    checked, offenders = 0, []
    for kernel in _kernels():
        for result in kernel.overloads.values():
            try:
                module = result.library._get_module_for_linking()
            except AttributeError:  # numba internals moved
                pytest.skip("numba's code library has no _get_module_for_linking")
            checked += 1
            if "raise_with_shape_context" in str(module):
                offenders.append(kernel.py_func.__qualname__)
    assert checked > 20  # at least the entry points, whose modules hold their callees' code
    assert offenders == []
