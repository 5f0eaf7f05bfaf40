"""Recognition: the feature method, the automatic threshold, the live index's sync and
the retention of inspection images."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field


class RecognitionFields(BaseModel):
    """Settings of recognition, the automatic threshold, the live index and image retention."""

    recognition_method: Literal["sift", "orb", "akaze", "color-sift"] = Field(
        "sift",
        description="Feature method of trained views and inspections (changing it makes the "
        "stored views stale until `visioncell models reextract`).",
    )
    recognition_max_features: int = Field(
        1000, ge=50, le=4000, description="Strongest keypoints kept per trained view."
    )
    recognise_max_images: int = Field(
        16, ge=1, le=64, description="Most images one POST /api/recognition/recognise takes."
    )
    threshold_follow: bool = Field(
        True,
        description="Recompute the automatic threshold as a job after every change of the "
        "trained views or negatives (off: only teaches recompute it).",
    )
    threshold_quiet_s: float = Field(
        2.0,
        ge=0.0,
        le=600.0,
        allow_inf_nan=False,
        description="The automatic threshold is recomputed once the trained views have not "
        "changed for this long, seconds (many uploads in a row: one recomputation).",
    )
    image_retention: Literal["all", "failures"] = Field(
        "all",
        description="Inspection images (and 3D scene recordings) kept: of every inspection, or "
        "of unknown and failed ones only.",
    )
    image_max_age_days: int | None = Field(
        None, ge=1, le=3650, description="Prune images older than this many days (None: never)."
    )
    image_max_bytes: int | None = Field(
        None,
        ge=1_000_000,
        le=2**50,
        description="Prune the oldest inspections' images beyond this many bytes (None: no cap).",
    )
    image_prune_interval_s: float = Field(
        3600.0, ge=10.0, le=7 * 86400.0, description="Period of the automatic prune, s."
    )
    index_poll_s: float = Field(
        2.0,
        ge=0.05,
        le=60.0,
        description="How often the live index checks the database for models and views "
        "changed by another process (cell or CLI) when it cannot LISTEN (SQLite, or the "
        "PostgreSQL listening connection lost), s.",
    )
    index_listen: bool = Field(
        True,
        description="On PostgreSQL, learn of other processes' model and view changes at once "
        "through LISTEN/NOTIFY (polling every index_poll_s otherwise).",
    )
