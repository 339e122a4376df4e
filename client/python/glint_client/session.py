"""Typed views of sessions: the steps and the final state as plain dataclasses, converted from
the `glint.v1` messages. Poses are `Pose`s (t_w_o: object → world, t_w_c: left camera →
world, metres); entropies in nats (None where the wire says NaN: a view chosen without
prediction); times in milliseconds."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any, Optional

from .pose import Pose


class ViewPolicy(str, enum.Enum):
    """How the next view is chosen (values are the CLI's names)."""

    NBV = "nbv"
    NBV_CONST_SIGMA = "nbv-const-sigma"
    RANDOM = "random"
    MAX_DISTANCE = "max-distance"

    @property
    def proto_name(self) -> str:
        return "VIEW_POLICY_" + self.name

    @staticmethod
    def parse(value: ViewPolicy | str) -> ViewPolicy:
        """From an enum or its name ("nbv", "max-distance", …); ValueError naming the choices."""
        if isinstance(value, ViewPolicy):
            return value
        try:
            return ViewPolicy(value)
        except ValueError:
            names = ", ".join(p.value for p in ViewPolicy)
            raise ValueError(f"unknown policy {value!r}; one of {names}") from None

    @staticmethod
    def from_proto(value: int, orchestrator_pb2: Any) -> Optional[ViewPolicy]:
        name = orchestrator_pb2.ViewPolicy.Name(value)
        return ViewPolicy[name.removeprefix("VIEW_POLICY_")] if name != "VIEW_POLICY_UNSPECIFIED" else None


class SessionState(str, enum.Enum):
    """A session's state; CONVERGED (entropy threshold), BUDGET_SPENT, CANCELLED and FAILED
    are final."""

    UNSPECIFIED = "unspecified"
    CREATED = "created"
    RUNNING = "running"
    CONVERGED = "converged"
    BUDGET_SPENT = "budget_spent"
    CANCELLED = "cancelled"
    FAILED = "failed"
    # The orchestrator stopped while the session ran; run_session resumes it.
    INTERRUPTED = "interrupted"

    @property
    def is_final(self) -> bool:
        return self in (SessionState.CONVERGED, SessionState.BUDGET_SPENT, SessionState.CANCELLED, SessionState.FAILED)

    @staticmethod
    def from_proto(value: int, orchestrator_pb2: Any) -> SessionState:
        return SessionState[orchestrator_pb2.SessionState.Name(value).removeprefix("SESSION_STATE_")]


def _nats(h: float) -> Optional[float]:
    """An entropy from the wire: NaN (no value) becomes None."""
    return None if math.isnan(h) else h


@dataclass(frozen=True)
class Step:
    """One step: the view taken (`view` indexes the session's candidates) and the pose refined
    on all views so far, with its entropy and what the planner predicted."""

    step: int
    view: int
    view_points: int
    total_points: int
    #: The refined pose, object → world.
    t_w_o: Pose
    entropy_nats: float
    #: What the planner predicted for this view before taking it (None: chosen without).
    predicted_entropy_nats: Optional[float]
    #: Every candidate's predicted entropy for the NEXT view (empty when the session ends
    #: here or the policy predicts nothing; None for a candidate without a prediction).
    candidate_entropies_nats: list[Optional[float]]
    capture_ms: float
    refine_ms: float
    predict_ms: float
    #: "converged", "max_iterations" or "diverged".
    refine_status: str
    #: The view chosen next; None when the session ends here.
    next_view: Optional[int]
    #: The view's left camera → world.
    t_w_c: Optional[Pose] = None
    plan_ms: float = 0.0
    #: The pose covariance's 21 upper-triangle entries (m², m·rad, rad²; left perturbation of
    #: t_o_w, translation first), row by row; None if the refiner gave none.
    covariance_upper: Optional[tuple[float, ...]] = None

    @staticmethod
    def from_proto(msg: Any) -> Step:
        times = msg.times
        return Step(
            step=msg.step,
            view=msg.view,
            view_points=msg.view_points,
            total_points=msg.total_points,
            t_w_o=Pose.from_proto(msg.t_w_o),
            entropy_nats=msg.entropy_nats,
            predicted_entropy_nats=_nats(msg.predicted_entropy_nats),
            candidate_entropies_nats=[_nats(h) for h in msg.candidate_entropies_nats],
            capture_ms=times.capture_ms,
            refine_ms=times.refine_ms,
            predict_ms=times.predict_ms,
            refine_status=msg.refine_status,
            next_view=msg.next_view if msg.HasField("next_view") else None,
            t_w_c=Pose.from_proto(msg.t_w_c) if msg.HasField("t_w_c") else None,
            plan_ms=times.plan_ms,
            covariance_upper=tuple(msg.covariance.upper) if msg.HasField("covariance") else None,
        )


@dataclass(frozen=True)
class Session:
    """A session as the orchestrator reports it."""

    session_id: str
    state: SessionState
    policy: Optional[ViewPolicy]
    max_views: int
    #: None: only the view budget stops the session.
    entropy_threshold_nats: Optional[float]
    steps: list[Step]
    #: Why the session failed, when it did.
    error: str
    part: str
    candidates_t_w_c: list[Pose] = field(default_factory=list)
    initial_t_w_o: Optional[Pose] = None

    @staticmethod
    def from_proto(msg: Any, orchestrator_pb2: Any) -> Session:
        return Session(
            session_id=msg.session_id,
            state=SessionState.from_proto(msg.state, orchestrator_pb2),
            policy=ViewPolicy.from_proto(msg.policy, orchestrator_pb2),
            max_views=msg.max_views,
            entropy_threshold_nats=msg.entropy_threshold_nats or None,
            steps=[Step.from_proto(s) for s in msg.steps],
            error=msg.error,
            part=msg.part,
            candidates_t_w_c=[Pose.from_proto(p) for p in msg.candidates_t_w_c],
            initial_t_w_o=Pose.from_proto(msg.initial_t_w_o) if msg.HasField("initial_t_w_o") else None,
        )
