"""initial schema

Revision ID: 0001
Revises: (none)
Create Date: 2026-11-22 02:24:04.920501
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

import backend.db.types

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:

    op.create_table(
        "cells",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("description", sa.Text(), nullable=False),
        sa.Column("created_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_cells")),
        sa.UniqueConstraint("name", name=op.f("uq_cells_name")),
    )
    op.create_table(
        "object_models",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column(
            "kind",
            sa.Enum("2d", "3d", name="object_kind", native_enum=False, length=16),
            nullable=False,
        ),
        sa.Column("sitting_base", sa.String(length=64), nullable=False),
        sa.Column("threshold", sa.Float(), nullable=True),
        sa.Column("description", sa.Text(), nullable=False),
        sa.Column("created_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.CheckConstraint(
            "threshold IS NULL OR (threshold >= 0 AND threshold <= 1)",
            name=op.f("ck_object_models_threshold_range"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_object_models")),
        sa.UniqueConstraint("name", name=op.f("uq_object_models_name")),
    )
    op.create_table(
        "recognition_settings",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("global_threshold", sa.Float(), nullable=False),
        sa.Column("chosen_by", sa.String(length=32), nullable=False),
        sa.Column("detail", sa.JSON(), nullable=False),
        sa.Column("created_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.CheckConstraint(
            "global_threshold >= 0 AND global_threshold <= 1",
            name=op.f("ck_recognition_settings_threshold_range"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_recognition_settings")),
    )
    op.create_table(
        "users",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("role", sa.String(length=16), nullable=False),
        sa.Column("created_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.Column("disabled", sa.Boolean(), nullable=False),
        sa.CheckConstraint(
            "role IN ('viewer', 'operator', 'engineer')", name=op.f("ck_users_role")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_users")),
        sa.UniqueConstraint("name", name=op.f("uq_users_name")),
    )
    op.create_table(
        "api_tokens",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("user_id", sa.Integer(), nullable=False),
        sa.Column("token_hash", sa.String(length=64), nullable=False),
        sa.Column("prefix", sa.String(length=12), nullable=False),
        sa.Column("label", sa.String(length=64), nullable=False),
        sa.Column("created_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.Column("last_used_at", backend.db.types.UTCDateTime(timezone=True), nullable=True),
        sa.Column("revoked", sa.Boolean(), nullable=False),
        sa.ForeignKeyConstraint(
            ["user_id"], ["users.id"], name=op.f("fk_api_tokens_user_id_users"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_api_tokens")),
        sa.UniqueConstraint("token_hash", name=op.f("uq_api_tokens_token_hash")),
    )
    with op.batch_alter_table("api_tokens", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_api_tokens_user_id"), ["user_id"], unique=False)

    op.create_table(
        "calibration_sessions",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("cell_id", sa.Integer(), nullable=False),
        sa.Column(
            "kind",
            sa.Enum("intrinsic", "hand_eye", name="calibration_kind", native_enum=False, length=16),
            nullable=False,
        ),
        sa.Column("source", sa.String(length=16), nullable=False),
        sa.Column("board", sa.JSON(), nullable=False),
        sa.Column("note", sa.Text(), nullable=False),
        sa.Column("created_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["cell_id"],
            ["cells.id"],
            name=op.f("fk_calibration_sessions_cell_id_cells"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_calibration_sessions")),
    )
    with op.batch_alter_table("calibration_sessions", schema=None) as batch_op:
        batch_op.create_index(
            batch_op.f("ix_calibration_sessions_cell_id"), ["cell_id"], unique=False
        )

    op.create_table(
        "inspections",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("cell_id", sa.Integer(), nullable=False),
        sa.Column("started_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.Column("finished_at", backend.db.types.UTCDateTime(timezone=True), nullable=True),
        sa.Column(
            "decision",
            sa.Enum(
                "recognized", "unknown", "failed", name="decision", native_enum=False, length=16
            ),
            nullable=False,
        ),
        sa.Column("model_id", sa.Integer(), nullable=True),
        sa.Column("score", sa.Float(), nullable=True),
        sa.Column("viewpoints_visited", sa.JSON(), nullable=False),
        sa.Column("object_pose", sa.JSON(), nullable=True),
        sa.Column("duration_s", sa.Float(), nullable=True),
        sa.Column("note", sa.Text(), nullable=False),
        sa.ForeignKeyConstraint(
            ["cell_id"], ["cells.id"], name=op.f("fk_inspections_cell_id_cells"), ondelete="CASCADE"
        ),
        sa.ForeignKeyConstraint(
            ["model_id"],
            ["object_models.id"],
            name=op.f("fk_inspections_model_id_object_models"),
            ondelete="SET NULL",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_inspections")),
    )
    with op.batch_alter_table("inspections", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_inspections_cell_id"), ["cell_id"], unique=False)
        batch_op.create_index(batch_op.f("ix_inspections_started_at"), ["started_at"], unique=False)

    op.create_table(
        "trained_views",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("model_id", sa.Integer(), nullable=False),
        sa.Column("viewpoint", sa.Integer(), nullable=False),
        sa.Column("image_png", sa.LargeBinary(), nullable=False),
        sa.Column("features", sa.LargeBinary(), nullable=False),
        sa.Column("descriptor_kind", sa.String(length=32), nullable=False),
        sa.Column("descriptor_version", sa.String(length=32), nullable=False),
        sa.Column("keypoint_count", sa.Integer(), nullable=False),
        sa.Column("created_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.CheckConstraint(
            "viewpoint BETWEEN 1 AND 3", name=op.f("ck_trained_views_viewpoint_range")
        ),
        sa.ForeignKeyConstraint(
            ["model_id"],
            ["object_models.id"],
            name=op.f("fk_trained_views_model_id_object_models"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_trained_views")),
    )
    with op.batch_alter_table("trained_views", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_trained_views_model_id"), ["model_id"], unique=False)

    op.create_table(
        "calibration_samples",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("session_id", sa.Integer(), nullable=False),
        sa.Column("index", sa.Integer(), nullable=False),
        sa.Column("image_png", sa.LargeBinary(), nullable=False),
        sa.Column("joints", sa.JSON(), nullable=True),
        sa.Column("T_base_ee", sa.JSON(), nullable=True),
        sa.Column("corners", sa.JSON(), nullable=True),
        sa.Column("accepted", sa.Boolean(), nullable=False),
        sa.Column("reason", sa.Text(), nullable=False),
        sa.Column("created_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["session_id"],
            ["calibration_sessions.id"],
            name=op.f("fk_calibration_samples_session_id_calibration_sessions"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_calibration_samples")),
        sa.UniqueConstraint("session_id", "index", name="uq_calibration_samples_session_index"),
    )
    with op.batch_alter_table("calibration_samples", schema=None) as batch_op:
        batch_op.create_index(
            batch_op.f("ix_calibration_samples_session_id"), ["session_id"], unique=False
        )

    op.create_table(
        "calibrations",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("cell_id", sa.Integer(), nullable=False),
        sa.Column("session_id", sa.Integer(), nullable=True),
        sa.Column(
            "kind",
            sa.Enum("intrinsic", "hand_eye", name="calibration_kind", native_enum=False, length=16),
            nullable=False,
        ),
        sa.Column("parameters", sa.JSON(), nullable=False),
        sa.Column("residuals", sa.JSON(), nullable=False),
        sa.Column("options", sa.JSON(), nullable=False),
        sa.Column("sample_count", sa.Integer(), nullable=False),
        sa.Column("rms_px", sa.Float(), nullable=True),
        sa.Column("active", sa.Boolean(), nullable=False),
        sa.Column("created_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["cell_id"],
            ["cells.id"],
            name=op.f("fk_calibrations_cell_id_cells"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["session_id"],
            ["calibration_sessions.id"],
            name=op.f("fk_calibrations_session_id_calibration_sessions"),
            ondelete="SET NULL",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_calibrations")),
    )
    with op.batch_alter_table("calibrations", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_calibrations_cell_id"), ["cell_id"], unique=False)
        batch_op.create_index(
            batch_op.f("ix_calibrations_session_id"), ["session_id"], unique=False
        )
        batch_op.create_index(
            "uq_calibrations_active",
            ["cell_id", "kind"],
            unique=True,
            sqlite_where=sa.text("active"),
            postgresql_where=sa.text("active"),
        )

    op.create_table(
        "inspection_images",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("inspection_id", sa.Integer(), nullable=False),
        sa.Column("viewpoint", sa.Integer(), nullable=False),
        sa.Column("image_jpeg", sa.LargeBinary(), nullable=False),
        sa.Column("scores", sa.JSON(), nullable=False),
        sa.Column("created_at", backend.db.types.UTCDateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["inspection_id"],
            ["inspections.id"],
            name=op.f("fk_inspection_images_inspection_id_inspections"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_inspection_images")),
    )
    with op.batch_alter_table("inspection_images", schema=None) as batch_op:
        batch_op.create_index(
            batch_op.f("ix_inspection_images_inspection_id"), ["inspection_id"], unique=False
        )


def downgrade() -> None:

    with op.batch_alter_table("inspection_images", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_inspection_images_inspection_id"))

    op.drop_table("inspection_images")
    with op.batch_alter_table("calibrations", schema=None) as batch_op:
        batch_op.drop_index(
            "uq_calibrations_active",
            sqlite_where=sa.text("active"),
            postgresql_where=sa.text("active"),
        )
        batch_op.drop_index(batch_op.f("ix_calibrations_session_id"))
        batch_op.drop_index(batch_op.f("ix_calibrations_cell_id"))

    op.drop_table("calibrations")
    with op.batch_alter_table("calibration_samples", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_calibration_samples_session_id"))

    op.drop_table("calibration_samples")
    with op.batch_alter_table("trained_views", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_trained_views_model_id"))

    op.drop_table("trained_views")
    with op.batch_alter_table("inspections", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_inspections_started_at"))
        batch_op.drop_index(batch_op.f("ix_inspections_cell_id"))

    op.drop_table("inspections")
    with op.batch_alter_table("calibration_sessions", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_calibration_sessions_cell_id"))

    op.drop_table("calibration_sessions")
    with op.batch_alter_table("api_tokens", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_api_tokens_user_id"))

    op.drop_table("api_tokens")
    op.drop_table("users")
    op.drop_table("recognition_settings")
    op.drop_table("object_models")
    op.drop_table("cells")
