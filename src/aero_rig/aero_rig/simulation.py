"""A plan through the simulated plant in one process, without middleware.

The same models as the simulated nodes (actuator dynamics, wing plant, pressure integration),
stepped in order: fast data for pipeline tests and benchmarks. It leaves out what only the
graph has: the actuator's safety governor and the stream timing.
"""

from dataclasses import dataclass

import numpy as np

from multisine_gen.plan import ExperimentPlan
from pitch_actuator.dynamics import ActuatorModel
from pressure_scanner.integration import PressureIntegrator
from wing_sim.plant import WingPlant
from wing_sim.wing_params import WingParams

T0_NS = 1_700_000_000_000_000_000  # the plan's t0 for simulated runs


@dataclass
class SimulatedRun:
    plan: ExperimentPlan
    stamps_ns: np.ndarray  # t0 + k/fs
    pitch_deg: np.ndarray  # measured pitch (the identification input)
    cl: np.ndarray  # C_l by pressure integration (the output)
    light_stall: np.ndarray  # plant truth: the light-stall regime, per sample (bool)


def simulate_plan(
    plan: ExperimentPlan, seed: int = 0, params: WingParams | None = None
) -> SimulatedRun:
    """The plan through actuator, wing (params: default wing if None) and lift integration."""
    command = np.radians(plan.command_deg())
    actuator = ActuatorModel(fs=plan.fs, seed=seed)
    pitch = np.empty(len(command))
    alpha = np.empty(len(command))
    for k, c in enumerate(command):
        sample = actuator.step(c)
        pitch[k], alpha[k] = sample.position_rad, sample.alpha_true_rad
    plant = WingPlant(params, seed=seed)
    pressures, truth = plant.simulate(alpha)
    integrator = PressureIntegrator(plant.taps)
    cl = integrator.integrate(pressures, pitch, plant.dynamic_pressure_pa).cl
    stamps = T0_NS + np.round(np.arange(len(command)) * 1e9 / plan.fs).astype(np.int64)
    return SimulatedRun(plan, stamps, np.degrees(pitch), cl, truth.light_stall.copy())
