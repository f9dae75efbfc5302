"""Several sensors per campaign (issue 12, branch multi).

Each measurement row names its sensor (backfilled from its campaign's one sensor; nullable
so that rows written by hand or by older tools stay insertable), and
the cursor's uniqueness becomes (campaign, sensor, step, position); a campaign records
the sensors it dropped (serial → reason) and its calibration per sensor (serial → id).

Revision ID: 0005_multi_sensor
Revises: 0003_web_tokens
Create Date: 2026-11-23 05:15:00
"""

from __future__ import annotations

import sqlalchemy as sa

from alembic import op

revision = "0005_multi_sensor"
down_revision = "0004_manual_placement"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("measurements") as batch:
        batch.add_column(sa.Column("sensor", sa.String(length=64), nullable=True))
    op.execute("UPDATE measurements SET sensor = (SELECT campaigns.sensor FROM campaigns "
               "WHERE campaigns.id = measurements.campaign_id)")
    with op.batch_alter_table("measurements") as batch:  # batch: SQLite cannot ALTER freely
        batch.drop_constraint("uq_meas_cursor", type_="unique")
        batch.create_unique_constraint("uq_meas_sensor_cursor",
                                       ["campaign_id", "sensor", "step", "position"])
        batch.create_index(batch.f("ix_measurements_sensor"), ["sensor"], unique=False)
    with op.batch_alter_table("campaigns") as batch:
        batch.add_column(sa.Column("sensors_dropped", sa.JSON(), nullable=True))
        batch.add_column(sa.Column("calibration_ids", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("campaigns") as batch:
        batch.drop_column("calibration_ids")
        batch.drop_column("sensors_dropped")
    with op.batch_alter_table("measurements") as batch:
        batch.drop_index(batch.f("ix_measurements_sensor"))
        batch.drop_constraint("uq_meas_sensor_cursor", type_="unique")
        batch.create_unique_constraint("uq_meas_cursor", ["campaign_id", "step", "position"])
        batch.drop_column("sensor")
