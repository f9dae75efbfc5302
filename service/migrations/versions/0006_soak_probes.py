"""Soak probes (issue 12, branch engine12): every die-temperature probe of a soak is stored.

The campaign measures the sensor's temperature_rate gain from them and a resumed
campaign reloads them ("store every measurement as it is taken").

Revision ID: 0006_soak_probes
Revises: 0005_multi_sensor
Create Date: 2026-11-23 06:40:00
"""

from __future__ import annotations

import sqlalchemy as sa

from alembic import op

revision = "0006_soak_probes"
down_revision = "0005_multi_sensor"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "soak_probes",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("sensor", sa.String(length=64), nullable=True),
        sa.Column("step", sa.Integer(), nullable=False),
        sa.Column("soak_start_t_s", sa.Float(), nullable=False),
        sa.Column("pose", sa.String(length=64), nullable=False),
        sa.Column("t_s", sa.Float(), nullable=False),
        sa.Column("setpoint_c", sa.Float(), nullable=False),
        sa.Column("chamber_c", sa.Float(), nullable=True),
        sa.Column("sensor_c", sa.Float(), nullable=True),
        sa.Column("ref_x", sa.Float(), nullable=True),
        sa.Column("ref_y", sa.Float(), nullable=True),
        sa.Column("ref_z", sa.Float(), nullable=True),
        sa.Column("ax", sa.Float(), nullable=False),
        sa.Column("ay", sa.Float(), nullable=False),
        sa.Column("az", sa.Float(), nullable=False),
        sa.Column("n", sa.Integer(), nullable=False),
        sa.ForeignKeyConstraint(["campaign_id"], ["campaigns.id"]),
        sa.PrimaryKeyConstraint("id"),
    )
    op.create_index(op.f("ix_soak_probes_campaign_id"), "soak_probes", ["campaign_id"],
                    unique=False)


def downgrade() -> None:
    op.drop_index(op.f("ix_soak_probes_campaign_id"), table_name="soak_probes")
    op.drop_table("soak_probes")
