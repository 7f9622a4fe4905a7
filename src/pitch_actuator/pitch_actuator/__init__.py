"""Pitch actuator: shared safety layer, simulated actuator node and UDP hardware driver node."""

from pitch_actuator.dynamics import ActuatorModel, ActuatorParams, ActuatorSample
from pitch_actuator.gust import FreeStreamGust
from pitch_actuator.safety import (
    ActuatorLimits,
    DiagnosticLevel,
    GovernorCounters,
    GovernorEvent,
    GovernorMode,
    GovernorStatus,
    LimitsError,
    SafetyGovernor,
)

__all__ = [
    "ActuatorLimits",
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
]
