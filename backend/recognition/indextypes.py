"""What the live index (:mod:`backend.recognition.index`) keeps of a model, what it tells of
its views (stale ones, a load's outcome) and what separates it from the database (a
:class:`IndexDiff` and the stored view rows it loads)."""

from __future__ import annotations

from dataclasses import dataclass

from backend.db.models import ObjectModel, TrainedView


@dataclass(frozen=True)
class IndexedModel:
    """What the index keeps about a model (from its database row)."""

    id: int
    name: str
    part: str
    sitting_base: str
    kind: str
    threshold: float | None
    """The model's own threshold (engineer's override), None for the automatic one."""
    height_m: float | None = None
    """Height above the sitting base, metres (stored with the model; None: not known)."""
    grasp_obj: tuple[float, float, float] | None = None
    """Suction point on the upper surface, object frame, metres (None: not stored)."""
    geometry_source: str = ""
    """``measured`` (by the teach: the pick searches near the height), ``entered`` (by an
    engineer: the pick goes to it) or empty (none stored)."""

    @classmethod
    def of(cls, row: ObjectModel) -> IndexedModel:
        from backend.recognition.models import grasp_of

        return cls(row.id, row.name, row.part, row.sitting_base, row.kind.value, row.threshold,
                   row.height_m, grasp_of(row), row.geometry_source or "")  # fmt: skip


@dataclass(frozen=True)
class StaleView:
    """A stored view left out of the index because its features are stale."""

    view_id: int
    model_id: int
    descriptor_kind: str
    descriptor_version: str
    reason: str


@dataclass(frozen=True)
class LoadReport:
    """Outcome of building the index from the database."""

    models: int
    views: int
    stale: tuple[StaleView, ...]
    seconds: float


@dataclass(frozen=True)
class IndexDiff:
    """What separates the index from a snapshot of the database (:meth:`LiveIndex.diff`)."""

    generation: int
    """The index's change count when the diff was taken (:meth:`LiveIndex.apply` checks it)."""
    put_models: tuple[IndexedModel, ...]
    drop_models: tuple[int, ...]
    remove_views: tuple[int, ...]
    load_views: tuple[int, ...]
    """Views to (re)load from the database: new ones, re-extracted ones, reused ids."""
    deferred: bool = False
    """Views added here in the last :data:`~backend.recognition.index.LOCAL_GRACE_S` were
    missing from the snapshot and kept (their transaction may not have committed yet): diff
    again later."""

    @property
    def empty(self) -> bool:
        return not (self.put_models or self.drop_models or self.remove_views or self.load_views)


#: A stored view as :meth:`LiveIndex.apply` takes it:
#: ``(view_id, model_id, viewpoint, features blob, descriptor kind, descriptor version)``.
ViewRow = tuple[int, int, int, bytes, str, str]
#: The columns of a :data:`ViewRow`, in its order (for ``select(*VIEW_ROW_COLUMNS)``).
VIEW_ROW_COLUMNS = (
    TrainedView.id,
    TrainedView.model_id,
    TrainedView.viewpoint,
    TrainedView.features,
    TrainedView.descriptor_kind,
    TrainedView.descriptor_version,
)
