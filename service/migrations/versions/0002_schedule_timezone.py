"""Schedules: the IANA time zone their cron expression reads in (NULL = UTC).

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-22 23:45:00
"""

from __future__ import annotations

import sqlalchemy as sa

from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("schedules") as batch:  # batch: SQLite cannot ALTER freely
        batch.add_column(sa.Column("timezone", sa.String(length=64), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("schedules") as batch:
        batch.drop_column("timezone")
