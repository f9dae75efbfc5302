"""Calibration parameters: each calibration's 12 SFEM parameter polynomials in their own table.

Lot statistics compute their medians and MADs over these rows in the database instead
of parsing every calibration's model document. Existing calibrations are backfilled.

Revision ID: 0007_calibration_parameters
Revises: 0006_soak_probes
Create Date: 2026-11-26 13:20:00
"""

from __future__ import annotations

import sqlalchemy as sa

from alembic import op

revision = "0007_calibration_parameters"
down_revision = "0006_soak_probes"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "calibration_parameters",
        sa.Column("calibration_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=16), nullable=False),
        sa.Column("sensor", sa.String(length=64), nullable=False),
        sa.Column("reported_model", sa.String(length=64), nullable=True),
        sa.Column("centre_c", sa.Float(), nullable=True),
        sa.Column("valid_lo_c", sa.Float(), nullable=True),
        sa.Column("valid_hi_c", sa.Float(), nullable=True),
        sa.Column("unit", sa.String(length=32), nullable=False),
        sa.Column("tempco_unit", sa.String(length=32), nullable=False),
        *(sa.Column(f"c{j}", sa.Float(), nullable=True) for j in range(11)),
        sa.ForeignKeyConstraint(["calibration_id"], ["calibrations.id"], ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("calibration_id", "name"),
    )
    op.create_index(op.f("ix_calibration_parameters_sensor"), "calibration_parameters",
                    ["sensor"], unique=False)
    # The rows of calibrations stored before this table existed, from their model documents.
    from service.db.calibration_parameters import backfill

    backfill(op.get_bind())


def downgrade() -> None:
    op.drop_index(op.f("ix_calibration_parameters_sensor"), table_name="calibration_parameters")
    op.drop_table("calibration_parameters")
