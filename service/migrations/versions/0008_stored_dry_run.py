"""The dry run's prediction is stored with its campaign (and schedule) at creation.

``GET /campaigns``, the SSE events and the dashboard read it instead of planning
the campaign again. Rows created before this revision have NULL: the service
computes their prediction once, on first read, and stores it.

Revision ID: 0008_stored_dry_run
Revises: 0007_calibration_parameters
Create Date: 2026-11-26 14:50:00
"""

from __future__ import annotations

import sqlalchemy as sa

from alembic import op

revision = "0008_stored_dry_run"
down_revision = "0007_calibration_parameters"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("campaigns") as batch:
        batch.add_column(sa.Column("dry_run", sa.JSON(), nullable=True))
    with op.batch_alter_table("schedules") as batch:
        batch.add_column(sa.Column("dry_run", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("schedules") as batch:
        batch.drop_column("dry_run")
    with op.batch_alter_table("campaigns") as batch:
        batch.drop_column("dry_run")
