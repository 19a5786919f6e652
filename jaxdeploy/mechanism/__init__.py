"""Planar multibody mechanisms: bodies, ideal joints, force elements, clearance joints."""

from .assembly import AssemblyError, ConsistentState, consistent_motion, consistent_state
from .bodies import GROUND, Body, Kinematics
from .clearance import RevoluteClearance
from .element import AbstractElement, Wrench
from .events import first_onset_times, lock_times, onset_counts
from .forces import (
    AppliedForce,
    AppliedTorque,
    CoilSpringDrive,
    Gravity,
    HingeFriction,
    Latch,
    PreloadedLatch,
    RotationalSpring,
    Spring,
)
from .joints import AngleDriver, Prismatic, Revolute, Weld
from .meters import (
    BalanceMeter,
    EnergyMeter,
    StepClock,
    add_clock,
    balance_metered,
    balance_metered_state,
    contact_history,
    energy_balance,
    energy_moved,
    extremes_at,
    merge_extremes,
    metered,
    metered_balance,
    step_log,
    unmetered_because,
    without_balance_meter,
)
from .system import Mechanism

__all__ = [
    "GROUND",
    "AbstractElement",
    "AngleDriver",
    "AppliedForce",
    "AppliedTorque",
    "AssemblyError",
    "Body",
    "CoilSpringDrive",
    "BalanceMeter",
    "EnergyMeter",
    "StepClock",
    "ConsistentState",
    "Gravity",
    "HingeFriction",
    "Kinematics",
    "Latch",
    "PreloadedLatch",
    "Mechanism",
    "Prismatic",
    "Revolute",
    "RevoluteClearance",
    "RotationalSpring",
    "Spring",
    "Weld",
    "Wrench",
    "add_clock",
    "balance_metered",
    "balance_metered_state",
    "consistent_motion",
    "consistent_state",
    "energy_balance",
    "energy_moved",
    "extremes_at",
    "contact_history",
    "first_onset_times",
    "lock_times",
    "onset_counts",
    "merge_extremes",
    "metered",
    "metered_balance",
    "step_log",
    "unmetered_because",
    "without_balance_meter",
]
