"""The documented table of error codes is the code's own."""

from __future__ import annotations

from pathlib import Path

from cloudsim.error_codes import CODES, describe, markdown_table
from docs_tools.reference import ERROR_CODES_TABLE


def test_the_documented_table_is_the_codes_table() -> None:
    # the site puts markdown_table() there (docs_tools/reference.py; tests/docs/test_site.py)
    documented = (Path(__file__).parents[1] / "docs" / "error-codes.md").read_text()
    assert ERROR_CODES_TABLE in documented
    assert all(f"| `{code}` |" in markdown_table() for code in CODES)


def test_every_code_has_its_cause_and_what_to_do() -> None:
    for code, entry in CODES.items():
        found = describe(code, rtf=0.7)
        assert found["code"] == code and found["cause"] == entry.cause
        assert found["remedy"] and found["figures"] == "rtf 0.7"
