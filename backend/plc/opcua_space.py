"""The address space of the cell's OPC UA server (:mod:`backend.plc.opcua`): its nodes
under ``Objects/VisionCell`` (laid out in that module's docstring), the result event type,
the methods, and the variables' values for one handshake snapshot (millimetres and degrees
at this edge, NaN for a missing pose).

Runs in the server's child process, with asyncua imported only by the functions that build
and write (the cell's process never imports it).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from backend.plc.words import PlcResult, Snapshot

__all__ = [
    "METHODS",
    "NAMESPACE",
    "AddressSpace",
    "Var",
    "build_address_space",
    "fill_event",
    "snapshot_values",
    "write_order",
]

NAMESPACE = "urn:visioncell:plc"

#: The methods the address space offers, as named there (each needs a callable).
METHODS = ("EnableTrigger", "Trigger", "StartRun", "StopRun", "Reset", "SelectRecipe",
           "AcknowledgeResult")  # fmt: skip

#: The variables of the presented result (written before its valid flag and the state).
_RESULT_WORDS = frozenset(
    ("InspectionId", "TriggerNumber", "Decision", "DecisionCode", "Model", "ModelId", "Score",
     "X_mm", "Y_mm", "Yaw_deg", "Bin", "BinName", "Duration_s")
)  # fmt: skip


def _mm(v: float | None) -> float:
    return float("nan") if v is None else round(v * 1000.0, 2)


def _deg(v: float | None) -> float:
    return float("nan") if v is None else round(math.degrees(v), 2)


@dataclass
class Var:
    """One variable node, its OPC UA type and the value written last."""

    node: Any
    vtype: Any
    value: Any = None


@dataclass
class AddressSpace:
    """The nodes the server writes: its variables by name and the result events."""

    #: The variables by browse name.
    variables: dict[str, Var]
    #: The ``InspectionResultEventType`` node.
    event_type: Any
    #: Sends that event from the ``VisionCell`` object.
    event_generator: Any


async def build_address_space(
    server: Any, methods: Mapping[str, Callable[..., Any]]
) -> AddressSpace:
    """Register :data:`NAMESPACE` on ``server`` and add the cell's objects, variables
    (with their initial values), result event type and methods (``methods``: a callable
    per name of :data:`METHODS`)."""
    from asyncua import ua

    missing = [m for m in METHODS if m not in methods]
    if missing:
        raise ValueError(f"methods must give every one of {METHODS}, missing {missing}")
    idx = await server.register_namespace(NAMESPACE)
    V = ua.VariantType
    cell = await server.nodes.objects.add_object(idx, "VisionCell")
    groups: dict[str, Any] = {}
    for g in ("StateMachine", "Status", "RecipeManagement", "ResultManagement"):
        groups[g] = await cell.add_object(idx, g)
    groups["Result"] = await groups["ResultManagement"].add_object(idx, "Result")
    spec: dict[str, list[tuple[str, Any, Any]]] = {
        "StateMachine": [("CurrentState", "Idle", V.String), ("CurrentStateCode", 0, V.Int32)],
        "Status": [("TriggerEnabled", False, V.Boolean), ("TriggerReady", False, V.Boolean),
                   ("Busy", False, V.Boolean), ("ResultsValid", False, V.Boolean),
                   ("Running", False, V.Boolean), ("EStop", False, V.Boolean),
                   ("ErrorCode", 0, V.UInt16), ("ErrorText", "", V.String),
                   ("Triggers", 0, V.UInt32), ("QueuedResults", 0, V.UInt32)],
        "RecipeManagement": [("ActiveRecipeId", 0, V.UInt16)],
        "Result": [("InspectionId", 0, V.UInt32), ("TriggerNumber", 0, V.UInt32),
                   ("Decision", "", V.String), ("DecisionCode", 0, V.UInt16),
                   ("Model", "", V.String), ("ModelId", 0, V.UInt32),
                   ("Score", float("nan"), V.Double), ("X_mm", float("nan"), V.Double),
                   ("Y_mm", float("nan"), V.Double), ("Yaw_deg", float("nan"), V.Double),
                   ("Bin", 0, V.UInt16), ("BinName", "", V.String),
                   ("Duration_s", 0.0, V.Double)],
    }  # fmt: skip
    variables: dict[str, Var] = {}
    for group, items in spec.items():
        for name, value, vtype in items:
            node = await groups[group].add_variable(idx, name, ua.Variant(value, vtype))
            variables[name] = Var(node, vtype, value)
    event_type = await server.create_custom_event_type(
        idx, "InspectionResultEventType", ua.ObjectIds.BaseEventType,
        [("InspectionId", V.UInt32), ("TriggerNumber", V.UInt32), ("Decision", V.String),
         ("Model", V.String), ("ModelId", V.UInt32), ("Score", V.Double), ("X_mm", V.Double),
         ("Y_mm", V.Double), ("Yaw_deg", V.Double), ("Bin", V.UInt16),
         ("Duration_s", V.Double)],
    )  # fmt: skip
    event_generator = await server.get_event_generator(event_type, cell)
    A = ua.Argument

    def arg(name: str, vtype: Any) -> Any:
        a = A()
        a.Name, a.DataType, a.ValueRank = name, ua.NodeId(vtype.value), -1
        return a

    m = methods
    await cell.add_method(idx, "EnableTrigger", m["EnableTrigger"], [arg("Enable", V.Boolean)], [])
    await cell.add_method(idx, "Trigger", m["Trigger"], [], [arg("TriggerNumber", V.UInt32)])
    await cell.add_method(idx, "StartRun", m["StartRun"], [arg("Count", V.UInt32)], [])
    await cell.add_method(idx, "StopRun", m["StopRun"], [], [])
    await cell.add_method(idx, "Reset", m["Reset"], [], [])
    await groups["RecipeManagement"].add_method(
        idx, "SelectRecipe", m["SelectRecipe"], [arg("RecipeId", V.UInt16)], []
    )
    await groups["ResultManagement"].add_method(
        idx, "AcknowledgeResult", m["AcknowledgeResult"], [arg("InspectionId", V.UInt32)],
        [arg("Acknowledged", V.Boolean)],
    )  # fmt: skip
    return AddressSpace(variables, event_type, event_generator)


def snapshot_values(snap: Snapshot) -> dict[str, Any]:
    """The variables' values for ``snap`` by name (the result's only when one is
    presented)."""
    r = snap.result
    values: dict[str, Any] = {
        "CurrentState": snap.state.label, "CurrentStateCode": int(snap.state),
        "TriggerEnabled": snap.trigger_enabled, "TriggerReady": snap.trigger_ready,
        "Busy": snap.busy, "ResultsValid": snap.results_valid, "Running": snap.running,
        "EStop": snap.estop, "ErrorCode": int(snap.error), "ErrorText": snap.error_text,
        "Triggers": snap.triggers % 2**32, "QueuedResults": snap.queued,
        "ActiveRecipeId": snap.recipe,
    }  # fmt: skip
    if r is not None:
        values.update({
            "InspectionId": r.inspection_id % 2**32, "TriggerNumber": r.trigger % 2**32,
            "Decision": r.decision, "DecisionCode": r.decision_code,
            "Model": r.model or "", "ModelId": r.model_id,
            "Score": float("nan") if r.score is None else float(r.score),
            "X_mm": _mm(r.x_m), "Y_mm": _mm(r.y_m), "Yaw_deg": _deg(r.yaw_rad),
            "Bin": r.bin, "BinName": r.bin_name or "", "Duration_s": r.duration_s,
        })  # fmt: skip
    return values


def write_order(values: Mapping[str, Any]) -> list[str]:
    """The names of ``values`` in the order to write them: the result's words first, its
    valid flag and the state after them (a client that sees the flag reads a whole
    result)."""
    return sorted(values, key=lambda k: k not in _RESULT_WORDS)


def fill_event(ev: Any, r: PlcResult) -> None:
    """Set the fields of a result event ``ev`` from the presented result ``r``."""
    ev.InspectionId, ev.TriggerNumber = r.inspection_id % 2**32, r.trigger % 2**32
    ev.Decision, ev.Model, ev.ModelId = r.decision, r.model or "", r.model_id
    ev.Score = float("nan") if r.score is None else float(r.score)
    ev.X_mm, ev.Y_mm, ev.Yaw_deg = _mm(r.x_m), _mm(r.y_m), _deg(r.yaw_rad)
    ev.Bin, ev.Duration_s = r.bin, r.duration_s
    ev.Severity = 100
