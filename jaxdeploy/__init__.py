"""jaxdeploy: differentiable dynamics of deployable mechanisms with rough clearance joints.

The names a user needs, in one place (the submodules behind them may move; these names stay):

* run a ready-made scene: `get_scene` / `SCENES`, `DeployArray`, `SliderCrank`, `Impact`,
  `Pendulum` (all `Scene`s), then `simulate` → `Trajectory`; many parameter sets at once with
  `simulate_batch`; the solver and its step control in one `StepControl`, built once and
  passed as `control=` to `simulate`, `simulate_batch`, `sweep.sweep`, `fit.fit` and
  `optimize.DesignProblem` (each scene's default is `scene.default_control`);
* build a mechanism: `Mechanism`, `Body`, the ideal joints `Revolute`, `Prismatic`, `Weld`,
  `AngleDriver`, the clearance joint `RevoluteClearance`, the force elements `Gravity`,
  `Spring`, `RotationalSpring`, `CoilSpringDrive`, `Latch`, `PreloadedLatch`, `AppliedForce`,
  `AppliedTorque`, and `consistent_state` for the initial state (`consistent_motion`: its
  pose and velocities alone, a smaller program); contact laws are in the module `contact`;
* the persistent caches: `enable_caches()` at the top of a script (or `JAXDEPLOY_CACHE_DIR`
  set before `import jaxdeploy`) keeps traced and compiled programs on disk, so a second
  process neither traces nor compiles what an earlier one did (the command line always does);
* read a run (a `Trajectory`): `Trajectory.contact_episodes()` (each clearance joint's impacts:
  onset, v⁻, separation, peak force, peak penetration, impulse), `clearance_joint_history`
  (each clearance joint's eccentricity, penetration and contact forces at the saved times),
  and the energy balance: simulate `metered(mechanism)`, then `energy_balance` (kinetic,
  potential, dissipated energy and the residual); docs/tutorial.md shows all three;
* identify, design and sweep: the modules `fit` (`fit.fit`, `fit.parameter_jacobian`),
  `optimize` (`optimize.optimize`, `optimize.DesignProblem`) and `sweep` (`sweep.sweep`,
  `sweep.load_sweep`). They are modules, not functions, because `jaxdeploy.fit`,
  `jaxdeploy.optimize` and `jaxdeploy.sweep` are subpackages: Python binds the name of an
  imported submodule on its package, so a function of the same name would be replaced by the
  module as soon as anything imported it.

Names are imported on first use (PEP 562 `__getattr__`), so `import jaxdeploy` stays as cheap as
importing JAX: the command-line help does not pay for diffrax, optax and the scenes.

Importing jaxdeploy switches JAX to float64: contact penetrations are micrometres on bodies that
move metres, and impact forces span ten decades, which float32 cannot resolve (diffrax's
documentation, "How to choose a solver", asks for 64-bit below tolerances of ~1e-8).
Simulation code assumes 64-bit throughout.

Importing jaxdeploy also adds `--xla_cpu_use_fusion_emitters=false` to `XLA_FLAGS` while JAX's
backend has not started: XLA then compiles the package's programs markedly faster, no slower to
run (`jaxdeploy/_xla_flags.py` has the measurements). A value of that flag in `XLA_FLAGS` wins;
`JAXDEPLOY_XLA_FLAGS=off` keeps XLA's default.
"""

import importlib
import os
from typing import TYPE_CHECKING

import jax

from . import _xla_flags
from ._version import __version__

jax.config.update("jax_enable_x64", True)

# XLA:CPU's faster-compiling code generator, unless the user chose otherwise or JAX already
# started (`_xla_flags`: what, when, and how to turn it off). Before anything compiles.
_xla_flags.apply_defaults()

if os.environ.get("JAXDEPLOY_CACHE_DIR", "").strip():
    # The variable asks for the caches in Python as on the command line (`enable_caches`;
    # "off" keeps them off). Here, before any simulation module imports equinox.
    from ._compilation_cache import enable_caches as _enable_caches

    _enable_caches()

# Public name -> the module that defines it (a module name maps to itself).
_EXPORTS = {
    # simulation
    "simulate": "jaxdeploy.simulation",
    "enable_caches": "jaxdeploy._compilation_cache",
    "Trajectory": "jaxdeploy.simulation",
    "StepControl": "jaxdeploy.solvers",
    "simulate_batch": "jaxdeploy.batch",
    # scenes
    "Scene": "jaxdeploy.scenes",
    "SCENES": "jaxdeploy.scenes",
    "get_scene": "jaxdeploy.scenes",
    "DeployArray": "jaxdeploy.scenes",
    "SliderCrank": "jaxdeploy.scenes",
    "Impact": "jaxdeploy.scenes",
    "Pendulum": "jaxdeploy.scenes",
    # building a mechanism
    "Mechanism": "jaxdeploy.mechanism",
    "Body": "jaxdeploy.mechanism",
    "Revolute": "jaxdeploy.mechanism",
    "Prismatic": "jaxdeploy.mechanism",
    "Weld": "jaxdeploy.mechanism",
    "AngleDriver": "jaxdeploy.mechanism",
    "RevoluteClearance": "jaxdeploy.mechanism",
    "Gravity": "jaxdeploy.mechanism",
    "Spring": "jaxdeploy.mechanism",
    "RotationalSpring": "jaxdeploy.mechanism",
    "CoilSpringDrive": "jaxdeploy.mechanism",
    "Latch": "jaxdeploy.mechanism",
    "PreloadedLatch": "jaxdeploy.mechanism",
    "AppliedForce": "jaxdeploy.mechanism",
    "AppliedTorque": "jaxdeploy.mechanism",
    "consistent_motion": "jaxdeploy.mechanism",
    "consistent_state": "jaxdeploy.mechanism",
    # outputs of a run beyond the saved states
    "metered": "jaxdeploy.mechanism",
    "energy_balance": "jaxdeploy.mechanism",
    "clearance_joint_history": "jaxdeploy.analysis",
}
_MODULES = ("contact", "mechanism", "solvers", "scenes", "analysis", "fit", "optimize", "sweep")

__all__ = [  # = _EXPORTS + _MODULES + __version__ (tests/test_public_api.py checks it)
    "SCENES",
    "AngleDriver",
    "AppliedForce",
    "AppliedTorque",
    "Body",
    "CoilSpringDrive",
    "DeployArray",
    "Gravity",
    "Impact",
    "Latch",
    "Mechanism",
    "PreloadedLatch",
    "Pendulum",
    "Prismatic",
    "Revolute",
    "RevoluteClearance",
    "RotationalSpring",
    "Scene",
    "SliderCrank",
    "Spring",
    "StepControl",
    "Trajectory",
    "Weld",
    "__version__",
    "analysis",
    "clearance_joint_history",
    "consistent_motion",
    "consistent_state",
    "contact",
    "energy_balance",
    "enable_caches",
    "fit",
    "get_scene",
    "mechanism",
    "metered",
    "optimize",
    "scenes",
    "simulate",
    "simulate_batch",
    "solvers",
    "sweep",
]


def __getattr__(name: str):
    if name in _MODULES:
        # Importing a submodule binds it on this package, so __getattr__ is not called again.
        return importlib.import_module(f"{__name__}.{name}")
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))


if TYPE_CHECKING:  # what the lazy names are, for type checkers and editors
    from . import analysis, contact, fit, mechanism, optimize, scenes, solvers, sweep
    from ._compilation_cache import enable_caches
    from .analysis import clearance_joint_history
    from .batch import simulate_batch
    from .mechanism import (
        AngleDriver,
        AppliedForce,
        AppliedTorque,
        Body,
        CoilSpringDrive,
        Gravity,
        Latch,
        Mechanism,
        PreloadedLatch,
        Prismatic,
        Revolute,
        RevoluteClearance,
        RotationalSpring,
        Spring,
        Weld,
        consistent_motion,
        consistent_state,
        energy_balance,
        metered,
    )
    from .scenes import SCENES, DeployArray, Impact, Pendulum, Scene, SliderCrank, get_scene
    from .simulation import Trajectory, simulate
    from .solvers import StepControl
