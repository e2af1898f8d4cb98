"""isf.compiled.flags: numba's flags hash and compare as numba defines it, only faster."""

import itertools

import pytest
from numba.core.compiler import Flags

from isf.compiled.flags import install


def _numbas_values(flags: Flags) -> dict:
    """numba's own definition of ``TargetConfig.values``: each option read through its
    property (the set value, else the option's default)."""
    return {name: getattr(flags, name) for name in type(flags).options}


def _flag_sets():
    """Flags with no option set, with options set to their defaults, and set to other values."""
    yield Flags()
    for names in (("nrt",), ("nrt", "no_cpython_wrapper"), ("boundscheck", "fastmath", "nrt")):
        for value in (False, True):
            flags = Flags()
            for name in names:
                setattr(flags, name, value)
            yield flags
    flags = Flags()
    flags.error_model = "numpy"
    flags.nrt = True
    yield flags


def test_installed_on_this_numba():
    assert install()
    assert install()  # a second call leaves it installed


@pytest.mark.parametrize("flags", list(_flag_sets()))
def test_values_are_numbas(flags):
    install()
    values = flags.values()
    assert values == _numbas_values(flags)
    assert list(values) == list(_numbas_values(flags))  # the same option order


def test_hash_and_equality_agree_with_numbas_definition():
    """Two flags are equal exactly when numba's option dicts are, and equal flags hash alike
    (an option set to its default equals it unset)."""
    install()
    for first, second in itertools.product(list(_flag_sets()), repeat=2):
        equal = _numbas_values(first) == _numbas_values(second)
        assert (first == second) is equal
        if equal:
            assert hash(first) == hash(second)
    unset, at_default = Flags(), Flags()
    at_default.boundscheck = Flags.options["boundscheck"].default
    assert unset == at_default and hash(unset) == hash(at_default)
