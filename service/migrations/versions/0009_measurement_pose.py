"""Every measurement keeps the pose the rig commanded for it (issue 22, turntable geometry).

``pose_qw, pose_qx, pose_qy, pose_qz``: the unit quaternion (scalar first, qw ≥ 0) of the
rotation mapping sensor to lab coordinates (drivers.geometry.pose_quaternion). With
``ref_*`` alone the heading of each pose about gravity is unknown, so a rotation fixed in
the lab frame (a tilted table base) cannot be tested. Rows stored before this revision,
and those of a hand-placed fixture, keep NULL: their pose is not known (no backfill).

Revision ID: 0009_measurement_pose
Revises: 0008_stored_dry_run
Create Date: 2026-11-28 02:10:00
"""

from __future__ import annotations

import sqlalchemy as sa

from alembic import op

revision = "0009_measurement_pose"
down_revision = "0008_stored_dry_run"
branch_labels = None
depends_on = None

POSE_COLUMNS = ("pose_qw", "pose_qx", "pose_qy", "pose_qz")


def upgrade() -> None:
    with op.batch_alter_table("measurements") as batch:
        for name in POSE_COLUMNS:
            batch.add_column(sa.Column(name, sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("measurements") as batch:
        for name in reversed(POSE_COLUMNS):
            batch.drop_column(name)
