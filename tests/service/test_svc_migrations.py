"""Alembic's head is exactly the schema of service/db/models.py, on SQLite and PostgreSQL."""

from __future__ import annotations

from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import Column, Integer, MetaData, inspect

from service.db.models import Base
from service.db.session import downgrade_database, make_engine, upgrade_database


def test_head_matches_the_models(migrated_db_url: str) -> None:
    diff = _diff(migrated_db_url, Base.metadata)
    assert diff == [], f"models and migrations differ: {diff}"


def test_the_comparison_sees_a_column_the_migrations_lack(migrated_db_url: str) -> None:
    drifted = MetaData()
    for table in Base.metadata.tables.values():
        table.to_metadata(drifted)
    drifted.tables["campaigns"].append_column(Column("operator_note_id", Integer))
    diff = _diff(migrated_db_url, drifted)
    assert [d[0] for d in diff] == ["add_column"] and d_name(diff[0]) == "operator_note_id"


def d_name(entry: tuple) -> str:  # ("add_column", schema, table, Column)
    return entry[3].name


def _diff(url: str, metadata: MetaData) -> list:
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            context = MigrationContext.configure(conn, opts={"compare_type": True})
            return compare_metadata(context, metadata)
    finally:
        engine.dispose()


def test_upgrade_is_idempotent_and_creates_every_table(db_url: str) -> None:
    upgrade_database(db_url)
    upgrade_database(db_url)  # a second service start finds nothing to do
    engine = make_engine(db_url)
    try:
        with engine.connect() as conn:
            tables = set(inspect(conn).get_table_names())
    finally:
        engine.dispose()
    assert set(Base.metadata.tables) | {"alembic_version"} == tables


def test_downgrade_to_base_drops_everything(db_url: str) -> None:
    upgrade_database(db_url)
    downgrade_database(db_url, "base")
    engine = make_engine(db_url)
    try:
        with engine.connect() as conn:
            assert set(inspect(conn).get_table_names()) <= {"alembic_version"}
    finally:
        engine.dispose()


def test_the_pose_columns_come_and_go_with_0009(db_url: str) -> None:
    """Migration 0009 adds the measurements' nullable pose quaternion and its downgrade
    drops it, on both backends (docs/recording.md, ``pose_q*``)."""
    pose = {"pose_qw", "pose_qx", "pose_qy", "pose_qz"}

    def columns() -> dict[str, bool]:
        engine = make_engine(db_url)
        try:
            with engine.connect() as conn:
                return {c["name"]: c["nullable"]
                        for c in inspect(conn).get_columns("measurements")}
        finally:
            engine.dispose()

    upgrade_database(db_url, "0008_stored_dry_run")
    assert not pose & set(columns())
    upgrade_database(db_url)
    cols = columns()
    assert pose <= set(cols) and all(cols[name] for name in pose)  # nullable: no backfill
    downgrade_database(db_url, "0008_stored_dry_run")
    assert not pose & set(columns()) and "ref_z" in columns()
