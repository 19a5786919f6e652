"""Constrained pendulum in absolute coordinates: a uniform rod pinned to the ground at one end.

The simplest index-3 DAE (3 coordinates, 2 constraints); used to measure convergence orders
and constraint drift of the integrators.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..mechanism import Body, Gravity, Mechanism, Revolute, consistent_state
from ..solvers.step_control import StepControl
from .base import ParamSpec, Scene


class Pendulum(Scene):
    name = "pendulum"
    params = {
        "length": ParamSpec(1.0, 0.0, float("inf"), "m", "rod length", low_inclusive=False),
        "mass": ParamSpec(1.0, 0.0, float("inf"), "kg", "rod mass", low_inclusive=False),
        "initial_angle": ParamSpec(0.0, -3.2, 3.2, "rad", "angle from +x at t = 0 (at rest)"),
        "gravity": ParamSpec(9.81, 0.0, 1e3, "m/s^2", "gravitational acceleration (−y)"),
    }
    default_t_end = 1.0
    default_control = StepControl(dt=1e-3)

    def build(self, params):
        length, mass = params["length"], params["mass"]
        rod = Body(
            "rod",
            mass=mass,
            inertia=mass * length**2 / 12.0,
            points={"pivot": jnp.stack([-0.5 * length, 0.0 * length])},
        )
        return Mechanism(
            [rod],
            [
                Revolute("ground", "O", "rod", "pivot"),
                Gravity(jnp.stack([0.0 * params["gravity"], -params["gravity"]])),
            ],
            ground_points={"O": (0.0, 0.0)},
        )

    def initial_state(self, params, mechanism):
        angle = jnp.asarray(params["initial_angle"], dtype=float)
        half = 0.5 * params["length"]
        q_guess = jnp.stack([half * jnp.cos(angle), half * jnp.sin(angle), angle])
        return consistent_state(mechanism, q_guess, fixed=(2,))
