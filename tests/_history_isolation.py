"""Keeps the test suite out of the user's history database (imported by conftest.py).

Every run the tests make (analyze, batch panes, web jobs, Python API) is recorded into a
history database of the session's temporary folder: ``GLASSDIST_DB`` and ``XDG_DATA_HOME``
point there for the whole session, child processes included. A test that needs a
database of its own sets ``GLASSDIST_DB`` again (``monkeypatch.setenv``).
"""

import pytest


@pytest.fixture(scope="session", autouse=True)
def isolated_history_db(tmp_path_factory):
    """``GLASSDIST_DB`` and ``XDG_DATA_HOME`` in the session's temporary folder; yields the database path."""
    root = tmp_path_factory.mktemp("history")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("XDG_DATA_HOME", str(root / "data"))
        mp.setenv("GLASSDIST_DB", str(root / "history.sqlite"))
        yield root / "history.sqlite"
