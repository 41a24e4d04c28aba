"""Persistence helpers: unique names are decided by the database, not by a look-up."""

from __future__ import annotations

import pytest

from backend.db.engine import make_engine, make_session_factory, upgrade_database
from backend.services.store import NameTakenError, add_catalog, find_catalog, stored_catalogs
from tofpose.core.catalog import paper_target


@pytest.fixture
def sessions(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'db.sqlite'}")
    upgrade_database(engine)
    yield make_session_factory(engine)
    engine.dispose()


def test_a_second_catalog_with_the_same_name_is_name_taken_and_the_first_survives(sessions):
    cat = paper_target()
    with sessions() as s:
        add_catalog(s, "mine", cat)
    with sessions() as s, pytest.raises(NameTakenError, match="'mine' already exists"):
        add_catalog(s, "mine", cat)  # as if a concurrent request had inserted it just now
    with sessions() as s:
        assert [n for n, _ in stored_catalogs(s)] == ["mine"]
        assert find_catalog(s, "mine") == cat
        add_catalog(s, "other", cat)  # the session is usable after the rollback


def test_a_built_in_name_cannot_be_stored(sessions):
    with sessions() as s, pytest.raises(NameTakenError, match="built in"):
        add_catalog(s, "paper-target", paper_target())
