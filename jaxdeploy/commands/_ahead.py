"""The run's program compiled ahead, in a second thread, while the command assembles the
initial state (`jaxdeploy simulate`).

The run's program depends on the initial state's shapes, not its values, and those follow
from the built mechanism alone (`abstract_state`). So once the mechanism is built, a thread
calls `simulate` with that abstract state inside `_program_cache.ahead_of_time()`: the
program is traced, stored and compiled while the main thread traces, compiles and runs the
assembly, and the run's own call then finds it ready (or waits for it: one lock per
program). XLA's compile and the waits for it leave Python's GIL free, so on two cores the
two compiles overlap. The traces would take turns (Python's GIL): traced beside the
assembly's, the run's trace and lowering took twice as long, and the run's compile, the
longest of the command's programs, began that much later. So the main thread waits for the
run's program to be traced (`wait_traced`) before it traces the assembly, which then fits
in the time XLA compiles the run's program (measured in `CompileAhead.wait_traced`).

Nothing is made ahead when the program cache is off (a plain `jit` call could not find the
program again), or when the step control would warn (`solver_advice`): the warning is the
run's to give, once.
"""

from __future__ import annotations

import threading
import time


def abstract_state(mechanism):
    """The `ConsistentState` `mechanism`'s initial state will have, as shapes and dtypes
    (`jax.ShapeDtypeStruct`): q, q̇, q̈ of its coordinates, λ of its constraints and the memory
    `Mechanism.init_memory` gives. Weak types dropped, as they are from the program cache's
    outputs, which the command's initial state is."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from ..mechanism import ConsistentState

    coordinates = jax.ShapeDtypeStruct((mechanism.n_coordinates,), jnp.float64)

    def state(q, v):
        lam = jnp.zeros((mechanism.n_constraints,), q.dtype)
        return ConsistentState(q, v, q, lam, mechanism.init_memory(q, v))

    shapes = eqx.filter_eval_shape(state, coordinates, coordinates)
    return jax.tree.map(lambda s: jax.ShapeDtypeStruct(s.shape, s.dtype), shapes)


class CompileAhead:
    """`start(mechanism)` begins compiling the program `simulate(mechanism, initial, t_end,
    n_save=n_save, control=control)` will run, in a daemon thread; `wait()` joins it and
    returns how long the caller waited [s]. Errors stay in the thread: the run's own call
    raises them again where they belong. `seconds`: the thread's wall time."""

    def __init__(self, t_end: float, n_save: int, control):
        self.t_end, self.n_save, self.control = t_end, n_save, control
        self._thread: threading.Thread | None = None
        self._traced = threading.Event()
        self.seconds = 0.0

    def start(self, mechanism) -> None:
        from .. import _program_cache
        from ..solvers import solver_advice

        if self._thread is not None or _program_cache.folder() is None:
            return
        if solver_advice(mechanism, self.control) is not None:
            return
        self._thread = threading.Thread(
            target=self._make, args=(mechanism,), name="compile-ahead", daemon=True
        )
        self._thread.start()

    def _make(self, mechanism) -> None:
        from .. import _program_cache
        from ..simulation import simulate

        began = time.time()
        try:
            initial = abstract_state(mechanism)
            with _program_cache.ahead_of_time(), _program_cache.when_traced(self._traced.set):
                simulate(mechanism, initial, self.t_end, n_save=self.n_save, control=self.control)
        except _program_cache.ProgramReady:
            pass  # made, or not cacheable: the run's call finds out
        except Exception:  # noqa: BLE001 - the run's own call raises it again, in its thread
            pass
        finally:
            self.seconds = time.time() - began
            self._traced.set()  # a caller of `wait_traced` never waits for more than this

    @property
    def started(self) -> bool:
        return self._thread is not None

    def wait_traced(self) -> float:
        """Wait until the run's program is traced and lowered (read back, or stored) and
        XLA compiles it, or until the thread ended (an error, an uncacheable call); at once
        when nothing was started. **Returns:** the wall time [s] this call waited.

        Why: two threads that trace take turns on Python's GIL. slider_crank's first run
        (`--rtol 1e-8 --atol 1e-11`, 2 cores, empty caches): traced beside the assembly, the
        run's trace took 2.8 s instead of 1.4–1.6 s, the assembly's trace and lowering 1.5
        and 1.7 s instead of 0.7 and 0.1 s, and XLA's compile of the run began 5.7 s after
        the start. Traced first, the run's program is in XLA's compile 4.0 s after the start
        (3.9–4.5 s, without the GIL) while the assembly traces, lowers and compiles. The
        whole process, 6 alternated pairs: 10.6 → 9.9 s (median; wall ratio 0.86).
        deploy_array's first run did not move (35.4 → 36.5 s, 3 pairs, ratio 0.96): its
        run's XLA compile (14.7 s) is longer than everything else the process does."""
        if self._thread is None:
            return 0.0
        began = time.time()
        self._traced.wait()
        return time.time() - began

    def wait(self) -> float:
        """Join the thread (a process must not end while it compiles: XLA aborts); the wall
        time [s] this call waited."""
        if self._thread is None:
            return 0.0
        began = time.time()
        self._thread.join()
        return time.time() - began


class Ahead:
    """`make(on_traced)` in a daemon thread named `name`, for a program a command needs later
    but can make now (`jaxdeploy fit`'s Jacobian, `jaxdeploy optimize`'s design batch): `make`
    traces it inside `_program_cache.ahead_of_time()` and calls `on_traced()` once it is
    traced (XLA's compile follows, without Python's GIL). The caller waits for the trace
    (`wait_traced`) before it traces anything of its own (two traces take turns on the GIL:
    `CompileAhead.wait_traced`), and joins the thread before the process ends (`join`: XLA
    aborts a process that ends while it compiles). Errors stay in the thread: the program's
    own call raises them again where they belong."""

    def __init__(self, name: str, make):
        self._traced = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(make,), name=name, daemon=True)
        self._thread.start()

    def _run(self, make) -> None:
        try:
            make(self._traced.set)
        except Exception:  # noqa: BLE001 - the program's own call raises it again, in its thread
            pass
        finally:
            self._traced.set()  # a caller of `wait_traced` never waits for more than this

    def wait_traced(self) -> None:
        self._traced.wait()

    def join(self) -> None:
        self._thread.join()
