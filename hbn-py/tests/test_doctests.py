"""Every example in the package's docstrings runs and prints what it says."""

import doctest

import hbn


def test_docstring_examples():
    result = doctest.testmod(hbn, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 50
    assert result.failed == 0, f"{result.failed} docstring examples failed (run doctest.testmod(hbn))"
