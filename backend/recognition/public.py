"""The public shapes of object models, trained views and negative images: what the CLI
prints and a teach job reports (the API adds the live index's counts, see
:mod:`backend.api.routes.modelforms`)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from backend.db.models import ObjectKind, ObjectModel, RecognitionSettings, TrainedView
from backend.publictypes import IsoTime
from backend.recognition.modelfields import grasp_of
from backend.recognition.thresholdadvice import recommended_rounds
from backend.recognition.thresholdstore import DEFAULT_THRESHOLD

__all__ = [
    "ModelPublic",
    "NegativePublic",
    "RecognitionSettingsPublic",
    "TeachRounds",
    "ViewDescriptor",
    "ViewPublic",
]


class TeachRounds(BaseModel):
    taught: int = Field(description="Teach rounds: distinct object yaws of the top views")
    recommended: int = Field(
        description="Rounds a model of this kind needs to be recognised at any yaw"
    )


class ModelPublic(BaseModel):
    """An object model with its trained views counted per viewpoint and its teach rounds."""

    id: int
    name: str
    part: str
    sitting_base: str
    kind: ObjectKind
    threshold: float | None
    description: str
    height_m: float | None = Field(description="Height above the sitting base, metres")
    grasp_obj: list[float] | None = Field(description="Suction point, object frame, metres")
    geometry_source: str = Field(description="measured (teach), entered (engineer) or empty")
    created_at: IsoTime
    views: int
    views_per_viewpoint: dict[str, int] = Field(description="Viewpoint -> trained views")
    rounds: TeachRounds

    @classmethod
    def of(
        cls, row: ObjectModel, counts: dict[int, int] | None = None, rounds: int = 0
    ) -> ModelPublic:
        """The public form of a model row (``counts``: trained views per viewpoint;
        ``rounds``: its teach rounds, shown beside the rounds its kind needs)."""
        counts = counts or {}
        grasp = grasp_of(row)
        return cls(
            id=row.id,
            name=row.name,
            part=row.part,
            sitting_base=row.sitting_base,
            kind=row.kind,
            threshold=row.threshold,
            description=row.description,
            height_m=row.height_m,
            grasp_obj=None if grasp is None else list(grasp),
            geometry_source=row.geometry_source or "",
            created_at=row.created_at,  # IsoTime writes it in ISO form
            views=sum(counts.values()),
            views_per_viewpoint={str(k): v for k, v in sorted(counts.items())},
            rounds=TeachRounds(taught=int(rounds), recommended=recommended_rounds(row.kind.value)),
        )


class ViewDescriptor(BaseModel):
    """The local features a view was trained with."""

    kind: str = Field(description="Feature method (vision.features.METHODS)")
    version: str = Field(description="Version of the features' format")


class ViewPublic(BaseModel):
    """A trained view (no image data) with the URLs of its image, thumbnail and mask."""

    id: int
    model_id: int
    viewpoint: int
    width: int = Field(description="Image width, pixels")
    height: int = Field(description="Image height, pixels")
    keypoints: int
    descriptor: ViewDescriptor
    yaw_rad: float
    roll_rad: float
    source: str = Field(description="teach (taken by the arm), upload or import")
    joints: list[float] | None = Field(description="Joint values q1..q5 it was taken at, rad")
    T_base_cam: list[list[float]] | None = Field(
        description="Camera pose in the base frame it was taken at (4x4, metres)"
    )
    created_at: IsoTime
    image_url: str
    thumbnail_url: str
    mask_url: str

    @classmethod
    def of(cls, row: TrainedView) -> ViewPublic:
        """The public form of a view row."""
        base = f"/api/models/{row.model_id}/views/{row.id}/image"
        return cls(
            id=row.id,
            model_id=row.model_id,
            viewpoint=row.viewpoint,
            width=row.width,
            height=row.height,
            keypoints=row.keypoint_count,
            descriptor=ViewDescriptor(kind=row.descriptor_kind, version=row.descriptor_version),
            yaw_rad=row.yaw_rad,
            roll_rad=row.roll_rad,
            source=row.source,
            joints=row.joints,
            T_base_cam=row.T_base_cam,
            created_at=row.created_at,  # IsoTime writes it in ISO form
            image_url=base,
            thumbnail_url=f"{base}?thumb=1",
            mask_url=f"{base}?mask=1",
        )


class NegativePublic(BaseModel):
    """A stored negative image (no image data)."""

    model_config = ConfigDict(from_attributes=True)

    id: int
    width: int = Field(description="Stored width, pixels")
    height: int = Field(description="Stored height, pixels")
    source: str
    note: str
    created_at: IsoTime


class RecognitionSettingsPublic(BaseModel):
    """The recognition settings in force: the global threshold and how it was chosen."""

    global_threshold: float = Field(description="Score above which a model is reported")
    chosen_by: Literal["default", "auto", "manual"] = Field(
        description="default (never chosen), auto (the automatic rule) or manual (an engineer)"
    )
    detail: dict[str, Any] = Field(
        description="How it was chosen; open because each way records its own: manual: by "
        "and note; auto: the rule, the per-model thresholds and the score distributions; "
        "default: empty"
    )
    created_at: IsoTime | None = Field(description="When it was chosen (None: the default)")

    @classmethod
    def of(cls, row: RecognitionSettings | None) -> RecognitionSettingsPublic:
        """The public form of the settings row in force (None: none was ever stored)."""
        if row is None:
            return cls(
                global_threshold=DEFAULT_THRESHOLD, chosen_by="default", detail={}, created_at=None
            )
        return cls(
            global_threshold=row.global_threshold,
            chosen_by=row.chosen_by,
            detail=row.detail,
            created_at=row.created_at,  # IsoTime writes it in ISO form
        )
