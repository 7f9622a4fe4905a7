"""Pitch actuator: shared safety layer, simulated actuator node and UDP hardware driver node."""

from pitch_actuator.dynamics import ActuatorModel, ActuatorParams, ActuatorSample
from pitch_actuator.gust import FreeStreamGust
from pitch_actuator.safety import (
    DiagnosticLevel,
    GovernorCounters,
    GovernorEvent,
    GovernorMode,
    GovernorStatus,
    LimitsError,
    SafetyGovernor,
    SafetyLimits,
)

__all__ = [
    "ActuatorModel",
    "ActuatorParams",
    "ActuatorSample",
    "DiagnosticLevel",
    "FreeStreamGust",
    "GovernorCounters",
    "GovernorEvent",
    "GovernorMode",
    "GovernorStatus",
    "LimitsError",
    "SafetyGovernor",
    "SafetyLimits",
]
