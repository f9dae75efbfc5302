"""Manual turntable: the pending hand-placement request per campaign (issue 9, branch manual).

Revision ID: 0004_manual_placement
Revises: 0003_web_tokens
Create Date: 2026-11-23 05:20:00
"""

from __future__ import annotations

import sqlalchemy as sa

from alembic import op

revision = "0004_manual_placement"
down_revision = "0003_web_tokens"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "placement_requests",
        sa.Column("campaign_id", sa.Integer(), sa.ForeignKey("campaigns.id"), primary_key=True),
        sa.Column("seq", sa.Integer(), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("ref_x", sa.Float(), nullable=False),
        sa.Column("ref_y", sa.Float(), nullable=False),
        sa.Column("ref_z", sa.Float(), nullable=False),
        sa.Column("instruction", sa.Text(), nullable=False),
        sa.Column("sketch", sa.Text(), nullable=False),
        sa.Column("reason", sa.Text(), nullable=True),
        sa.Column("state", sa.String(length=16), nullable=False),
        sa.Column("requested_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("confirmed_at", sa.DateTime(timezone=True), nullable=True),
    )


def downgrade() -> None:
    op.drop_table("placement_requests")
