"""The one table of errors (fxis_shm.errors.ERROR_TABLE): every error class and wire code has
its row, and docs/cli.md's tables are the ones generated from the code (issue 43)."""

from __future__ import annotations

import inspect
import pathlib

from fxis_shm import errors
from fxis_shm.cli import exitcodedocs, exitcodes
from fxis_shm.errors import ERROR_TABLE, Code, FxisError, ServiceError, service_error

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_docs_cli_md_holds_the_tables_generated_from_the_code():
    document = (ROOT / "docs" / "cli.md").read_text()
    assert exitcodedocs.with_table(document) == document, (
        "docs/cli.md differs from the code's tables: run python -m fxis_shm.cli.exitcodedocs --write docs/cli.md"
    )
    assert exitcodedocs.markdown_table() in document and exitcodedocs.ranges_table() in document


def test_every_error_class_has_one_row_and_every_wire_code_one_class():
    classes = [cls for _, cls in inspect.getmembers(errors, inspect.isclass) if issubclass(cls, FxisError)]
    named = [cls for cls, _, _ in ERROR_TABLE]
    assert sorted(c.__name__ for c in classes) == sorted(c.__name__ for c in named if issubclass(c, FxisError))
    assert len(named) == len(set(named))
    wires = [wire for _, _, wire in ERROR_TABLE if wire is not None]
    assert sorted(wires) == sorted(Code.ALL)  # each code exactly once
    for cls, code, wire in ERROR_TABLE:
        assert code in exitcodes.MEANINGS
        if wire is not None:
            raised = service_error(wire, "why")
            assert type(raised) is cls and raised.code == wire and isinstance(raised, ServiceError)
            assert exitcodes.for_error(raised) == code


def test_a_refused_setting_is_usage_and_a_refused_request_is_a_failure():
    assert exitcodes.for_error(service_error(Code.SETTING_REFUSED, "gain 30 > 24")) == exitcodes.USAGE
    assert exitcodes.for_error(service_error(Code.BAD_REQUEST, "why")) == exitcodes.FAILED
    assert exitcodes.for_error(service_error(Code.CAMERA_DOWN, "why")) == exitcodes.FAILED
    assert exitcodes.for_error(service_error("NOT_A_CODE", "why")) == exitcodes.FAILED  # a newer service's code
    assert exitcodes.for_error(errors.RequestTimeout("no reply")) == exitcodes.NO_SERVICE  # (an OSError too)
    assert exitcodes.for_error(KeyboardInterrupt()) == exitcodes.INTERRUPTED
    assert exitcodes.for_error(OSError(28, "No space left", "/x")) == exitcodes.FAILED
    assert exitcodes.for_error(PermissionError(13, "Permission denied", "/x")) == exitcodes.USAGE
    assert exitcodes.for_error(ValueError("a bug")) is None


def test_the_readme_links_to_the_table_instead_of_copying_it():
    readme = (ROOT / "README.md").read_text()
    assert "docs/cli.md#the-fxis-command-errors-and-exit-codes" in readme
    assert "0 done, 1 done" not in readme
