"""The core's library documentation (docs/api.md): every example in it runs, and every answer
it shows is the one the core gives."""
from __future__ import annotations

import doctest
from pathlib import Path

DOC = Path(__file__).resolve().parents[2] / "docs" / "api.md"


def test_every_example_of_the_api_document_runs_as_shown():
    result = doctest.testfile(str(DOC), module_relative=False,
                              optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 60  # the page is examples, not prose
    assert result.failed == 0
