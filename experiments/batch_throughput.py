"""Batch throughput: cost per simulation in one vmapped batch of B cases relative to the same
simulations run one at a time with the same solver, measured side by side in one run
(compilation timed separately, ahead of time).

    PYTHONPATH=. python experiments/batch_throughput.py [--scene deploy_array] [--batch 256]
        [--t-end 0.01] [--repeats 1] [--solver generalized_alpha tsit5 ...]
        [--groups all,32] [--sorted] [--lanes 16] [--segment-steps 8] [--two-cores lanes:16]
        [--out docs/batch_throughput.json] [--doc PAGE]

The B cases scatter the varied parameters around the scene's defaults (deploy_array: panel1_ra,
panel2_ra, panel1_clearance, panel2_clearance), x_i = x0 e^{s ξ_i}, ξ_i ~ N(0, 1) seeded, s =
`--spread` (default 0.1: the manufacturing-scatter use case of robust design), so the batch is
not one case repeated.

For every `--solver` (`generalized_alpha`: the default, modified Newton;
`generalized_alpha_full`: Newton proper; any other name of `jaxdeploy.solvers.SOLVER_NAMES`,
e.g. `tsit5`, the index-1 ODE with projection) the same B cases are run:

* `alone`: each case by itself, one after another (the program compiled at batch size 1):
  one simulation's cost is their mean. The same work as a batch, and as long, so that both
  see the shared machine's load alike;
* one row per `--groups` entry: `all`, one vmap over all B cases; an integer G, vmapped
  groups of G consecutive cases run one after another inside one compiled program
  (`batch_function(group_size=G)`);
* with `--sorted`, the same groups over the cases reordered by their step count alone (an
  oracle: the best any ordering can do; see the page);
* one row per `--lanes` entry L: the cases in L vmapped lanes, a lane that finishes its case
  taking the next after at most `--segment-steps` steps (`batch_function(lanes=L)`,
  `jaxdeploy.lanes`);
* with `--two-cores POLICY` (e.g. `lanes:16`), the batch sharded over 2 forced host devices
  (`XLA_FLAGS=--xla_force_host_platform_device_count=2`, as `jaxdeploy sweep` runs) in a
  child process pinned to two cores, each device running the policy on its half of the
  cases, timed in turn with the rows above. Its wall-time ratio to the 1-core `alone` run is
  throughput on this CPU (two cores against one), its CPU-time ratio the cost per
  core-second.

Times are medians over `--repeats` interleaved calls of the compiled programs (every variant
once per repeat, in turn); the ratio to the same solver's `alone` row, not the absolute time,
is the result (the machine is shared). A batch's cost is split into two measured factors:
**idle** = (case-steps the batch loop ran: every case of a group runs as many loop iterations
as the group's slowest case) / (steps the cases take alone), and **per-step gain** = (time
per step alone) / (time per case-step in the batch). The speed-up per case is their quotient.
The result JSON is rewritten (atomically) after every repeat, so an interrupted run keeps the
repeats it finished; `--from-json` rewrites the page from it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxdeploy
from jaxdeploy.batch import _stack_cases, batch_function, step_control
from jaxdeploy.io import atomic_write_bytes, atomic_write_json, run_metadata
from jaxdeploy.scenes import get_scene
from jaxdeploy.solvers import SOLVER_NAMES, GeneralizedAlpha

VARIED = {
    "deploy_array": ("panel1_ra", "panel2_ra", "panel1_clearance", "panel2_clearance"),
    "slider_crank": ("clearance",),
}
# Solver choices: generalized-α by Newton variant, then the index-1 ODE methods by name.
SOLVERS = (
    "generalized_alpha",
    "generalized_alpha_full",
    *(name for name in SOLVER_NAMES if name != "generalized_alpha"),
)
SOLVER_TITLES = {
    "generalized_alpha": 'generalized-α, modified Newton (`newton="modified"`)',
    "generalized_alpha_full": 'generalized-α, Newton proper (`newton="full"`)',
}
DEFAULT_SOLVER = "generalized_alpha"


def solver_argument(name: str):
    """What `simulate(solver=...)` gets for the solver choice `name`."""
    if name == "generalized_alpha":
        return GeneralizedAlpha()
    if name == "generalized_alpha_full":
        return GeneralizedAlpha(newton="full")
    return name  # simulate resolves the name (solver_by_name, with the step control's tolerances)


def cases(scene, batch, spread, seed):
    rng = np.random.default_rng(seed)
    defaults = scene.default_params()
    return {
        name: defaults[name] * np.exp(spread * rng.standard_normal(batch))
        for name in VARIED[scene.name]
    }


def parse_groups(text: str) -> list:
    """`"all,32"` -> `["all", 32]`, refusing anything else by name."""
    groups = []
    for item in text.split(","):
        item = item.strip()
        if item == "all":
            groups.append("all")
        elif item.isdigit() and int(item) >= 1:
            groups.append(int(item))
        else:
            raise SystemExit(f"--groups: {item!r} is invalid; give 'all' or integers ≥ 1")
    return groups


def parse_lanes(text: str) -> list[int]:
    """`"8,16"` -> `[8, 16]` (empty: none), refusing anything else by name."""
    out = []
    for item in filter(None, (x.strip() for x in text.split(","))):
        if not (item.isdigit() and int(item) >= 1):
            raise SystemExit(f"--lanes: {item!r} is invalid; give integers ≥ 1")
        out.append(int(item))
    return out


def policy_steps_run(steps, policy: dict, devices: int = 1, segment: int = 8) -> int:
    """Case-steps a batch policy (`jaxdeploy.sweep.parse_policy` form) runs over `steps`
    split evenly over `devices`, each device running the policy on its consecutive share."""
    steps = np.asarray(steps)
    total = 0
    for part in np.split(steps, devices):
        if policy["kind"] == "lanes":
            total += lane_steps_run(part, policy["lanes"], policy.get("segment_steps", segment))
        else:
            total += case_steps_run(part, policy.get("group_size", "all"))
    return total


class TwoCores:
    """The batch sharded over 2 forced host devices, in a child process pinned to `cores`
    (this process is pinned to one; XLA's device count is fixed when JAX starts, hence the
    child). It compiles on start and times one call per `run()`, so that its calls take
    turns with this process's rows under the same load."""

    def __init__(self, argv, solver, cores):
        import subprocess

        env = dict(os.environ)
        flags = env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
        env["XLA_FLAGS"] = flags.strip()
        env["BATCH_THROUGHPUT_CORES"] = ",".join(str(c) for c in cores)
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
        command = [sys.executable, os.path.abspath(__file__), *argv, "--child"]
        command += ["--solver", solver]
        self.process = subprocess.Popen(
            command, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        self.compile_s = self._answer()["ready"]

    def _answer(self) -> dict:
        for line in self.process.stdout:
            if line.startswith("@@"):
                return json.loads(line[2:])
        raise RuntimeError(f"--two-cores child ended (exit code {self.process.wait()})")

    def run(self):
        """`(wall s, CPU s of the child, counts)` of one call of the sharded batch."""
        from types import SimpleNamespace

        self.process.stdin.write("run\n")
        self.process.stdin.flush()
        got = self._answer()
        counts = SimpleNamespace(
            stats={k: np.asarray(got[k]) for k in ("num_steps", "num_accepted_steps")},
            result=SimpleNamespace(_value=np.asarray(got["result"])),
        )
        return got["wall"], got["cpu"], counts

    def close(self):
        self.process.stdin.close()
        self.process.wait()


def child(args) -> None:
    """`--two-cores`'s child (see `TwoCores`): compile the sharded batch, then time one call
    per `run` line on stdin, answering `@@{json}` lines on stdout."""
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    from jaxdeploy.sweep import _policy_options, parse_policy

    cores = {int(c) for c in os.environ["BATCH_THROUGHPUT_CORES"].split(",")}
    for task in os.listdir("/proc/self/task"):
        os.sched_setaffinity(int(task), cores)
    devices = jax.devices()
    if len(devices) != 2:
        raise SystemExit(f"--two-cores child: {len(devices)} devices, 2 expected")
    sharding = NamedSharding(Mesh(np.array(devices), ("cases",)), PartitionSpec("cases"))
    scene = get_scene(args.scene)
    table, varied, shared = _stack_cases(
        scene, cases(scene, args.batch, args.spread, args.seed), None
    )
    ts = jnp.linspace(0.0, args.t_end, args.n_save)
    policy = parse_policy(args.two_cores)
    if policy["kind"] == "lanes" and ":" not in args.two_cores[len("lanes:") :]:
        policy["segment_steps"] = args.segment_steps
    program = batch_function(
        scene,
        varied,
        shared,
        args.t_end,
        ts,
        solver=solver_argument(args.solver[0]),
        sharding=sharding,
        **_policy_options(policy),
    )
    inputs = tuple(jax.device_put(jnp.asarray(table[k]), sharding) for k in varied)
    start = time.perf_counter()
    compiled = program.lower(inputs).compile()
    print("@@" + json.dumps({"ready": time.perf_counter() - start}), flush=True)
    for line in sys.stdin:
        if line.strip() != "run":
            break
        wall, cpu, (out,) = time_batch(compiled, inputs)
        answer = {
            "wall": wall,
            "cpu": cpu,
            "num_steps": _per_case([out], "num_steps"),
            "num_accepted_steps": _per_case([out], "num_accepted_steps"),
            "result": [int(x) for x in np.ravel(np.asarray(out.result._value))],
        }
        print("@@" + json.dumps(answer), flush=True)


def group_slices(batch: int, group) -> list[slice]:
    """The cases each vmapped group holds: `lax.map(batch_size=G)` runs consecutive groups of
    G and the remainder as one last group."""
    size = batch if group == "all" else group
    return [slice(i, min(i + size, batch)) for i in range(0, batch, size)]


def case_steps_run(steps, group) -> int:
    """Case-steps a batch loop runs: each group iterates as often as its slowest case (every
    case of it taking every iteration, masked once finished)."""
    steps = np.asarray(steps)
    return int(sum((s.stop - s.start) * steps[s].max() for s in group_slices(len(steps), group)))


def lane_steps_run(steps, lanes: int, segment: int) -> int:
    """Case-steps a lane-refilled batch runs (`jaxdeploy.lanes`), replaying its schedule from
    the cases' step counts: every segment, each of the `lanes` lanes (busy or not) takes as
    many loop iterations as the busiest lane takes steps in it (≤ `segment`); a lane whose
    case finished takes the next case in order for the next segment."""
    pending = [int(n) for n in steps]
    lanes = min(lanes, len(pending))
    left = pending[:lanes]  # steps each lane's case still needs (0: idle)
    following = lanes
    total = 0
    while any(left):
        taken = [min(n, segment) for n in left]
        total += lanes * max(taken)
        left = [n - k for n, k in zip(left, taken, strict=True)]
        for i, n in enumerate(left):
            if n == 0 and taken[i] > 0 and following < len(pending):
                left[i] = pending[following]
                following += 1
    return total


def _label(policy) -> str:
    kind, group = policy
    if kind == "alone":
        return "alone"
    if kind == "lanes":
        return f"{group} lanes, refilled"
    name = "vmap all" if group == "all" else f"groups of {group}"
    return name + (", sorted" if kind == "sorted" else "")


def pin_cores(count: int) -> list[int]:
    """Pin every thread of this process to the first `count` of its allowed cores (0: leave
    as is); the cores it runs on.

    XLA's CPU client runs independent operations of one program on several threads. Unpinned
    on this shared 2-core machine, a simulation alone used both cores when the other users
    left one idle and one when they did not, and a batch differently again, so the wall-time
    ratio followed the machine's load rather than the batch. Pinned, wall and CPU time are
    both the cost on `count` cores.
    """
    allowed = sorted(os.sched_getaffinity(0))
    if count < 0 or count > len(allowed):
        raise SystemExit(f"--cores {count} is invalid: give 0 (no pinning) to {len(allowed)}")
    if count == 0:
        return allowed
    chosen = set(allowed[:count])
    for task in os.listdir("/proc/self/task"):  # threads already started (e.g. by imports)
        os.sched_setaffinity(int(task), chosen)
    return sorted(chosen)


def time_alone(program, singles):
    """Every case alone, one after another: `(wall s, CPU s, trajectories)` for all."""
    start, start_cpu = time.perf_counter(), time.process_time()
    outs = [program(case) for case in singles]
    jax.block_until_ready(outs)
    wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
    return wall, cpu, outs


def time_batch(program, inputs):
    """`(wall s, CPU s of this process, [trajectory])` of one call."""
    start, start_cpu = time.perf_counter(), time.process_time()
    out = program(inputs)
    jax.block_until_ready(out)
    return time.perf_counter() - start, time.process_time() - start_cpu, [out]


def _per_case(outs, key) -> list[int]:
    return [int(x) for o in outs for x in np.ravel(np.asarray(o.stats[key]))]


def _ok(outs) -> int:
    return sum(int(np.sum(np.asarray(o.result._value) == 0)) for o in outs)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="deploy_array", choices=sorted(VARIED))
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--t-end", type=float, default=0.01)
    ap.add_argument("--n-save", type=int, default=11)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--spread", type=float, default=0.1, help="log-normal scatter s")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--solver", nargs="+", default=[DEFAULT_SOLVER, "tsit5"], choices=SOLVERS, metavar="S"
    )
    ap.add_argument("--groups", default="all,32", help="'all' and/or group sizes, comma-separated")
    ap.add_argument(
        "--sorted",
        action="store_true",
        help="also run the integer groups over the cases sorted by their steps alone",
    )
    ap.add_argument(
        "--lanes", default="", help="lane counts of refilled-lane rows, comma-separated"
    )
    ap.add_argument("--segment-steps", type=int, default=8, help="steps between refills")
    ap.add_argument(
        "--two-cores",
        default=None,
        metavar="POLICY",
        help="also run the batch sharded over 2 devices on 2 cores with this policy "
        "(jaxdeploy.sweep.parse_policy: all, groups:G, lanes:L[:K])",
    )
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--no-parts", action="store_true", help="skip the Newton-iteration parts")
    ap.add_argument(
        "--cores",
        type=int,
        default=1,
        help="pin the process to this many cores (0: no pinning); see pin_cores",
    )
    ap.add_argument("--out", default=None, help="write the result as JSON here")
    ap.add_argument("--doc", default=None, help="write a generated markdown page here")
    ap.add_argument(
        "--from-json", default=None, help="only rewrite --doc from a stored --out result"
    )
    args = ap.parse_args(argv)
    argv = sys.argv[1:] if argv is None else list(argv)

    if args.from_json:
        with open(args.from_json) as fh:
            stored = json.load(fh)
        atomic_write_bytes(args.doc, page(stored).encode())
        return stored
    if args.batch < 1:
        raise SystemExit(f"--batch {args.batch} is invalid: it must be ≥ 1")
    if args.child:
        return child(args)
    allowed = sorted(os.sched_getaffinity(0))
    cores = pin_cores(args.cores)
    groups = parse_groups(args.groups)
    lanes = parse_lanes(args.lanes)
    if args.segment_steps < 1:
        raise SystemExit(f"--segment-steps {args.segment_steps} is invalid: it must be ≥ 1")
    two_cores = None
    if args.two_cores is not None:
        from jaxdeploy.sweep import parse_policy

        try:
            two_cores = parse_policy(args.two_cores)
        except ValueError as err:
            raise SystemExit(f"--two-cores: {err}") from None
        if len(allowed) < 2 or args.batch % 2:
            raise SystemExit("--two-cores needs 2 allowed cores and an even --batch")
    scene = get_scene(args.scene)
    table, varied, shared = _stack_cases(
        scene, cases(scene, args.batch, args.spread, args.seed), None
    )
    ts = jnp.linspace(0.0, args.t_end, args.n_save)
    stacked = tuple(jnp.asarray(table[k]) for k in varied)
    singles = [tuple(v[i : i + 1] for v in stacked) for i in range(args.batch)]

    result = {
        "scene": args.scene,
        "batch": args.batch,
        "t_end": args.t_end,
        "n_save": args.n_save,
        "spread": args.spread,
        "seed": args.seed,
        "varied": varied,
        "cases": {k: [float(x) for x in table[k]] for k in varied},
        "solvers": list(args.solver),
        "groups": groups,
        "lanes": lanes,
        "segment_steps": args.segment_steps,
        "two_cores_policy": two_cores,
        "control": step_control(scene).settings(),
        "cores": cores,
        "cores_requested": args.cores,
        "versions": run_metadata(),
        "jaxdeploy_version": jaxdeploy.__version__,
        "argv": argv,
        "repeats_done": 0,
        "runs": {},
    }

    def save():
        if args.out:
            atomic_write_json(args.out, result)

    # Every (solver, policy) compiled ahead of time.
    programs = {}
    for solver in args.solver:
        make = lambda group, solver=solver, **policy: batch_function(  # noqa: E731
            scene,
            varied,
            shared,
            args.t_end,
            ts,
            group_size=group,
            solver=solver_argument(solver),
            **policy,
        )
        policies = [("alone", None)] + [("given", g) for g in groups]
        if args.sorted:
            policies += [("sorted", g) for g in groups if g != "all"]
        policies += [("lanes", n) for n in lanes]
        for kind, group in policies:
            label = _label((kind, group))
            inputs = singles[0] if kind == "alone" else stacked
            if kind == "sorted":  # the same program as the unsorted groups: only data differ
                compiled = programs[(solver, _label(("given", group)))][2]
                compile_s = result["runs"][solver][_label(("given", group))]["compile_s"]
            else:
                if kind == "lanes":
                    program = make(None, lanes=group, segment_steps=args.segment_steps)
                else:
                    program = make(None if group in (None, "all") else group)
                start = time.perf_counter()
                compiled = program.lower(inputs).compile()
                compile_s = time.perf_counter() - start
            programs[(solver, label)] = (kind, group, compiled)
            result["runs"].setdefault(solver, {})[label] = {
                "kind": kind,
                "group": group,
                "compile_s": compile_s,
                "walls_s": [],
                "cpus_s": [],
            }
            print(f"{solver} / {label}: compiled in {compile_s:.1f} s", flush=True)
        if two_cores is not None:
            process = TwoCores(argv, solver, allowed[:2])
            label = f"2 cores: {args.two_cores}"
            programs[(solver, label)] = ("two_cores", None, process)
            result["runs"][solver][label] = {
                "kind": "two_cores",
                "group": None,
                "policy": two_cores,
                "cores": allowed[:2],
                "compile_s": process.compile_s,
                "walls_s": [],
                "cpus_s": [],
            }
            print(f"{solver} / {label}: compiled in {process.compile_s:.1f} s", flush=True)

    # Interleaved: every variant once per repeat, so that all see the same load. The sorted
    # order comes from the first repeat's `alone` run of the same solver (its steps per case).
    for repeat in range(args.repeats):
        for (solver, label), (kind, _group, compiled) in programs.items():
            record = result["runs"][solver][label]
            if kind == "alone":
                wall, cpu, outs = time_alone(compiled, singles)
                order = np.arange(args.batch)
            elif kind == "two_cores":
                wall, cpu, counts = compiled.run()
                order = np.arange(args.batch)
                outs = [counts]
            else:
                if kind == "sorted":
                    alone_steps = result["runs"][solver]["alone"]["num_steps"]
                    order = np.argsort(alone_steps, kind="stable")
                else:
                    order = np.arange(args.batch)
                inputs = tuple(v[order] for v in stacked) if kind == "sorted" else stacked
                wall, cpu, outs = time_batch(compiled, inputs)
            record["walls_s"].append(wall)
            record["cpus_s"].append(cpu)
            # Per case, in the original case order.
            back = np.argsort(order)
            for key in ("num_steps", "num_accepted_steps"):
                record[key] = [int(x) for x in np.asarray(_per_case(outs, key))[back]]
            record["order"] = [int(i) for i in order]
            record["ok"] = _ok(outs)
            print(
                f"repeat {repeat + 1}: {solver} / {label}: {wall:.2f} s wall, {cpu:.2f} s CPU "
                f"for {args.batch} cases, {record['ok']} ok",
                flush=True,
            )
        result["repeats_done"] = repeat + 1
        derive(result)
        save()

    for kind, _group, program in programs.values():
        if kind == "two_cores":
            program.close()
    sizes = [g for g in groups if g != "all"]
    if not args.no_parts:
        # Where a step's time goes, per case: alone and in a vmapped group.
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        from step_profile import _case_parts

        size = sizes[0] if sizes else args.batch
        dt = 1e-4 if args.scene == "deploy_array" else 1e-6
        result["parts"] = {"dt": dt, "group_size": size}
        for key, group in (("alone", None), ("group", size)):
            if any(s.startswith("generalized_alpha") for s in args.solver):
                result["parts"][key] = _case_parts(args.scene, False, dt, 3, 500, group)
            if any(not s.startswith("generalized_alpha") for s in args.solver):
                result["parts"][f"ode_{key}"] = ode_parts(args.scene, 3, 500, group)
            print("parts", key, result["parts"], flush=True)
    result["complete"] = True
    save()
    if args.doc:
        atomic_write_bytes(args.doc, page(result).encode())
    return result


def ode_parts(scene_name, repeats, calls, batch=None) -> dict:
    """µs of CPU per call of the index-1 ODE path's parts (`jaxdeploy.solvers.index1`), for
    one case; with `batch`, per case of a vmapped group of `batch` cases: one evaluation of
    the accelerations q̈(q, q̇) (Tsit5 takes 6 per step) and the projection onto the
    constraints after a step. Timed like `step_profile._case_parts`: each part called `calls`
    times in one compiled `lax.scan`, the mechanism a traced argument."""
    from step_profile import _cpu, _setup

    from jaxdeploy.solvers.index1 import project_onto_constraints, stabilised_accelerations

    _, mech, s0 = _setup(scene_name, False)
    memory = mech.memory_for_step(s0.memory, s0.q, s0.v)
    n = s0.q.shape[0]
    pieces = {
        "accelerations q̈(q, q̇)": lambda mech, x: stabilised_accelerations(
            mech, x[:n], x[n:], 0.0, memory
        )[0],
        "projection": lambda mech, x: jnp.concatenate(
            project_onto_constraints(mech, x[:n], x[n:], 0.0)
        ),
    }
    x0 = jnp.concatenate([s0.q, s0.v])
    size = 1 if batch is None else batch
    z0 = x0 if batch is None else jnp.tile(x0, (batch, 1))
    out = {}
    for name, fn in pieces.items():
        each = fn if batch is None else jax.vmap(fn, in_axes=(None, 0))

        @jax.jit
        def loop(mech, z, each=each):
            def body(c, _):
                r = each(mech, c)  # a nonlinear use of the output, as in _case_parts
                return c + 1e-30 * jnp.sum(r * r), None

            return jax.lax.scan(body, z, None, length=calls)[0]

        _, cpu = _cpu(lambda loop=loop: jax.block_until_ready(loop(mech, z0)), repeats)
        out[name] = cpu / calls / size * 1e6
    return out


def derive(r) -> None:
    """The ratios, from the medians of the timings so far (in place)."""
    for runs in r["runs"].values():
        alone = runs["alone"]
        alone_steps = np.asarray(alone["num_steps"])
        for rec in runs.values():
            rec["wall_s"] = float(np.median(rec["walls_s"]))
            rec["cpu_s"] = float(np.median(rec["cpus_s"]))
            rec["steps_mean"] = float(np.mean(rec["num_accepted_steps"]))
            rec["steps_max"] = int(np.max(rec["num_accepted_steps"]))
        for rec in runs.values():
            rec["speedup"] = alone["wall_s"] / rec["wall_s"]
            rec["cpu_speedup"] = alone["cpu_s"] / rec["cpu_s"]
            # Paired by repeat (each batch call beside the alone run of the same repeat).
            rec["speedups"] = [a / b for a, b in zip(alone["walls_s"], rec["walls_s"], strict=True)]
            if rec["kind"] == "alone":
                rec["case_steps_run"] = int(alone_steps.sum())
                continue
            # The groups hold the cases in the order the batch got them.
            steps_in_order = np.asarray(rec["num_steps"])[rec["order"]]
            if rec["kind"] == "lanes":
                policy = {"kind": "lanes", "lanes": rec["group"]}
                rec["case_steps_run"] = policy_steps_run(
                    steps_in_order, policy, segment=r["segment_steps"]
                )
            elif rec["kind"] == "two_cores":
                rec["case_steps_run"] = policy_steps_run(
                    steps_in_order, rec["policy"], devices=2, segment=r["segment_steps"]
                )
            else:
                rec["case_steps_run"] = case_steps_run(steps_in_order, rec["group"])
            rec["idle"] = rec["case_steps_run"] / int(alone_steps.sum())
            rec["per_step_gain"] = (alone["wall_s"] / int(alone_steps.sum())) / (
                rec["wall_s"] / rec["case_steps_run"]
            )
    # Against generalized-α alone: only once every solver's medians exist (it may come later).
    if DEFAULT_SOLVER in r["runs"]:
        base = r["runs"][DEFAULT_SOLVER]["alone"]
        for runs in r["runs"].values():
            for rec in runs.values():
                rec["speedup_vs_default_alone"] = base["wall_s"] / rec["wall_s"]
                rec["cpu_speedup_vs_default_alone"] = base["cpu_s"] / rec["cpu_s"]


def _rank_correlation(x, y) -> float:
    """Spearman's ρ (ties broken by order; enough for a correlation this rough)."""
    rx, ry = (np.argsort(np.argsort(a)).astype(float) for a in (x, y))
    return float(np.corrcoef(rx, ry)[0, 1])


def _case_values(r) -> dict:
    """The batch's varied parameters per case (stored, or drawn again from the seed)."""
    if "cases" in r:
        return {k: np.asarray(v) for k, v in r["cases"].items()}
    return cases(get_scene(r["scene"]), r["batch"], r["spread"], r["seed"])


def _title(solver) -> str:
    return SOLVER_TITLES.get(solver, f"`{solver}` (index-1 ODE with projection)")


def _best(runs) -> tuple[str, dict]:
    """The batch policy on one core (in the given case order) with the largest speed-up,
    wall and CPU."""
    given = {k: v for k, v in runs.items() if v["kind"] in ("given", "lanes")}
    label = max(given, key=lambda k: min(given[k]["speedup"], given[k]["cpu_speedup"]))
    return label, given[label]


def _met(rec) -> bool:
    return rec["speedup"] >= 2 and rec["cpu_speedup"] >= 2


def _solver_table(r, runs) -> str:
    rows = []
    for label, rec in runs.items():
        each = rec["speedups"]
        spread = f"{min(each):.2f}–{max(each):.2f}" if len(each) > 1 else f"{each[0]:.2f}"
        name = label + (" (oracle order)" if rec["kind"] == "sorted" else "")
        if rec["kind"] == "two_cores":
            name += " (wall: 2 cores vs 1)"
        speedup = (
            "1"
            if rec["kind"] == "alone"
            else f"**{rec['speedup']:.2f}** ({rec['cpu_speedup']:.2f}); {spread}"
        )
        idle = "1" if rec["kind"] == "alone" else f"{rec['idle']:.2f}"
        gain = "1" if rec["kind"] == "alone" else f"{rec['per_step_gain']:.2f}"
        rows.append(
            f"| {name} | {rec['wall_s']:.2f} | {rec['wall_s'] / r['batch']:.4f} | {speedup} | "
            f"{rec['steps_mean']:.0f} ({rec['steps_max']}) | {idle} | {gain} | "
            f"{rec['ok']}/{r['batch']} | {rec['compile_s']:.0f} |"
        )
    head = (
        "| policy | wall [s], all cases | per case [s] | speed-up per case (CPU); "
        "per repeat | accepted steps per case: mean (max) | idle | per-step gain | ok | "
        "compile [s] |\n|---|---|---|---|---|---|---|---|---|"
    )
    return head + "\n" + "\n".join(rows)


def _verdict(solver, runs) -> str:
    label, rec = _best(runs)
    wall, cpu = rec["speedup"], rec["cpu_speedup"]
    sorted_runs = {k: v for k, v in runs.items() if v["kind"] == "sorted"}
    oracle = ""
    if sorted_runs:
        o_label, o = max(
            sorted_runs.items(), key=lambda kv: min(kv[1]["speedup"], kv[1]["cpu_speedup"])
        )
        oracle = (
            f" With the cases ordered by their step count (an oracle, {o_label}): "
            f"{o['speedup']:.2f}× ({o['cpu_speedup']:.2f}× in CPU time)."
        )
    if _met(rec):
        return (
            f"**Target met for {_title(solver)}**: {label} is {wall:.2f}× cheaper per "
            f"simulation than the same solver alone ({cpu:.2f}× in CPU time).{oracle}"
        )
    worse = ": it costs more per simulation than running the cases alone" if wall < 1 else ""
    return (
        f"**Target not met for {_title(solver)}**: the best batch policy in the cases' own "
        f"order, {label}, has a speed-up of {wall:.2f} per simulation over the same solver "
        f"alone ({cpu:.2f} in CPU time){worse}, ≥ 2 wanted; its idle factor "
        f"{rec['idle']:.2f} divides a per-step gain of {rec['per_step_gain']:.2f}.{oracle}"
    )


def _parts_table(parts) -> str:
    g = parts["group_size"]
    rows = []
    for kind, names in (
        ("", ("residual r(z)", "iteration matrix", "factorisation", "solve with factors")),
        ("ode_", ("accelerations q̈(q, q̇)", "projection")),
    ):
        alone, group = parts.get(f"{kind}alone"), parts.get(f"{kind}group")
        if alone is None:
            continue
        path = "generalized-α" if not kind else "index-1 ODE (Tsit5 & co.)"
        for name in names:
            ratio = alone[name] / group[name] if group[name] > 0 else float("nan")
            rows.append(
                f"| {path} | {name} | {alone[name]:.2f} | {group[name]:.2f} | {ratio:.2f} |"
            )
    return (
        f"| path | part | alone [µs] | per case in a vmapped group of {g} [µs] | ratio |\n"
        "|---|---|---|---|---|\n" + "\n".join(rows)
    )


def _why(r) -> str:
    runs = r["runs"]
    values = _case_values(r)
    lines = []
    for solver, rs in runs.items():
        steps = np.asarray(rs["alone"]["num_steps"])
        lo, med, hi = np.percentile(steps, [0, 50, 100])
        rho = {k: _rank_correlation(v, steps) for k, v in values.items()}
        strongest = max(rho, key=lambda k: abs(rho[k]))
        vmap = rs.get("vmap all")
        same = ""
        if vmap is not None:
            batch_steps = np.asarray(vmap["num_steps"])
            same = (
                f"; in the vmap, {np.mean(batch_steps == steps):.0%} of the cases take exactly "
                f"the steps they take alone (rank correlation "
                f"{_rank_correlation(batch_steps, steps):.2f})"
            )
        lines.append(
            f"* {_title(solver)}: steps (accepted + rejected) per case alone {lo:.0f}, "
            f"median {med:.0f}, largest {hi:.0f}; the parameter most correlated with them is "
            f"{strongest} (rank correlation {rho[strongest]:+.2f}){same}."
        )
    return "\n".join(lines)


def _solver_comparison(r) -> str:
    runs = r["runs"]
    if DEFAULT_SOLVER not in runs or len(runs) < 2:
        return ""
    base = runs[DEFAULT_SOLVER]["alone"]
    rows = []
    for solver, rs in runs.items():
        label, rec = _best(rs)
        rows.append(
            f"| {_title(solver)} | {rs['alone']['wall_s'] / r['batch']:.4f} | "
            f"{base['wall_s'] / rs['alone']['wall_s']:.2f} | {label} | "
            f"{rec['wall_s'] / r['batch']:.4f} | {rec['speedup_vs_default_alone']:.2f} "
            f"({rec['cpu_speedup_vs_default_alone']:.2f}) |"
        )
    return (
        "\n## Across solvers (same run)\n\nThe accuracy of the solvers differs at the same "
        "tolerance (docs/performance.md), so this compares costs, not cost at equal accuracy. "
        "Speed-ups against one simulation alone with generalized-α, modified Newton (CPU time in "
        "brackets):"
        "\n\n| solver | one simulation alone [s] | alone vs generalized-α alone | best batch "
        "policy | per case [s] | best batch vs generalized-α alone |\n|---|---|---|---|---|---|\n"
        + "\n".join(rows)
        + "\n"
    )


def _parts_reading(parts) -> str:
    """What the parts table says, from its ratios (alone over per case in a group)."""
    if not parts:
        return ""
    ratios = {}
    for kind in ("", "ode_"):
        alone, group = parts.get(f"{kind}alone"), parts.get(f"{kind}group")
        if alone is not None:
            ratios.update({(kind, k): alone[k] / group[k] for k in alone if k != "size"})
    text = [
        f"Each part of a step (table below) costs {min(ratios.values()):.1f}–"
        f"{max(ratios.values()):.1f}× less per case in a vmapped group of "
        f"{parts['group_size']} than alone (compare the per-step "
        "gains in the tables above)."
    ]
    if "alone" in parts:
        cheap = ratios[("", "residual r(z)")], ratios[("", "solve with factors")]
        dear = ratios[("", "iteration matrix")], ratios[("", "factorisation")]
        text.append(
            "Modified Newton's iterations are mostly a residual and a solve with stored "
            f"factors (ratios {cheap[0]:.2f} and {cheap[1]:.2f}); Newton proper also forms "
            f"and factorises the matrix at every iteration ({dear[0]:.2f} and {dear[1]:.2f})."
        )
    if "ode_alone" in parts:
        text.append(
            "A Tsit5 step is seven evaluations of the index-1 accelerations (six stages and "
            "one at the projected step end, which is also the next step's first stage; each a "
            "constrained linear solve, "
            f"{ratios[('ode_', 'accelerations q̈(q, q̇)')]:.2f}) and one "
            f"projection onto the constraints ({ratios[('ode_', 'projection')]:.2f})."
        )
    return " ".join(text)


def _density(r) -> str:
    solver = DEFAULT_SOLVER if DEFAULT_SOLVER in r["runs"] else next(iter(r["runs"]))
    steps = r["runs"][solver]["alone"]["steps_mean"]
    return f"{steps / (r['t_end'] * 1e3):.0f} accepted steps per simulated ms with {solver} here"


def _why_summary(r) -> str:
    """Speed-up = per-step gain / idle, with the ranges this run measured."""
    batches = [
        rec
        for runs in r["runs"].values()
        for rec in runs.values()
        if "idle" in rec and rec["kind"] != "two_cores"
    ]
    gains = [rec["per_step_gain"] for rec in batches]
    idles = [rec["idle"] for rec in batches]
    return (
        f"Speed-up per case = per-step gain / idle. Over every solver and policy here the "
        f"per-step gain is {min(gains):.2f}–{max(gains):.2f} and idle {min(idles):.2f}–"
        f"{max(idles):.2f}; "
        + (
            "2× would need a per-step gain of at least 2 even with no idle steps at all, "
            "which no policy measured here reaches."
            if max(gains) < 2
            else "the target needs a per-step gain of at least 2 × idle."
        )
    )


def _cores_text(r) -> str:
    cores = r.get("cores")
    if not cores:
        return ""
    if len(cores) > 1 and r.get("cores_requested", 1) == 0:
        return (
            f"The process ran unpinned on {len(cores)} cores (`--cores 0`): XLA may run a "
            "program's independent operations on several threads, so the ratios also hold "
            "how each configuration's threading fared under the load of the moment."
        )
    return (
        f"The process ran pinned to {len(cores)} core(s) (`--cores`, `pin_cores`). Unpinned "
        "(`--cores 0`), XLA spreads one program's many small operations over threads: a "
        "simulation alone then used the second core whenever other users left it idle, and "
        "cost more CPU time in thread hand-offs, which a batch's larger operations hide; the "
        "ratios of this benchmark's unpinned runs were larger and followed the machine's load. "
        "Pinned, a ratio is the cost on the same core(s); for throughput on several cores, "
        "run one pinned process per core."
    )


def _control_text(control) -> str:
    return ", ".join(
        f"{k} {val:g}" if isinstance(val, int | float) else f"{k} {val}"
        for k, val in control.items()
    )


def _two_cores_text(r) -> str:
    """The two-core rows' verdicts: throughput on this CPU (wall) and cost per core (CPU)."""
    lines = []
    for solver, runs in r["runs"].items():
        for label, rec in runs.items():
            if rec["kind"] != "two_cores":
                continue
            met = "meets" if rec["speedup"] >= 2 else "does not meet"
            lines.append(
                f"* {_title(solver)}, `{label[len('2 cores: ') :]}` on each of 2 devices: "
                f"**{rec['speedup']:.2f}×** the throughput of one simulation at a time on one "
                f"core (wall time; this {met} the 2× target on the whole CPU), "
                f"{rec['cpu_speedup']:.2f}× in CPU time (cost per core-second: the per-core "
                "comparison)."
            )
    if not lines:
        return ""
    return (
        "\n## Both cores\n\nThe batch sharded over 2 forced host devices "
        "(`XLA_FLAGS=--xla_force_host_platform_device_count=2`, as `jaxdeploy sweep` runs), "
        "each device running the policy on its half of the cases, in a child process pinned "
        "to both cores, timed in turn with the rows above (`--two-cores`). Its wall-time "
        "ratio to the one-core `alone` run compares two cores with one, so it is the "
        "throughput this CPU gains, not a cost per simulation; its CPU-time ratio is the "
        "cost per core-second (it includes the second core's share, and whatever other "
        "users took from it stretches the wall time only).\n\n" + "\n".join(lines) + "\n"
    )


def _revision(versions) -> str:
    git = versions.get("git") or {}
    if not isinstance(git, dict) or "commit" not in git:
        return "?"
    return git["commit"][:7] + (" with uncommitted changes" if git.get("dirty") else "")


def page(r) -> str:
    command = "PYTHONPATH=. python experiments/batch_throughput.py " + " ".join(r["argv"])
    v = r["versions"]
    done = r["repeats_done"]
    sections = []
    for solver, runs in r["runs"].items():
        sections.append(
            f"### {_title(solver)}\n\n{_solver_table(r, runs)}\n\n{_verdict(solver, runs)}\n"
        )
    parts = r.get("parts")
    parts_text = (
        f"""The parts of a step, measured by this run (µs of CPU per case, each part called 500
times in one compiled loop, state of the first step, h = {parts["dt"]:g} s for generalized-α;
`experiments/step_profile.py`'s method):

{_parts_table(parts)}
"""
        if parts
        else ""
    )
    size = (parts or {}).get("alone", {}).get("size")
    size_text = f" (generalized-α's Newton system is {size} × {size})" if size else ""
    incomplete = "" if r.get("complete") else f"\n**Incomplete run: {done} repeat(s) finished.**\n"
    return f"""# Batch throughput (generated)

*Written by `{command.strip()}`; rerun it to regenerate. Machine: {v["platform"]},
{len(v["devices"])} device(s), jax {v["jax"]}, code {_revision(v)}; shared by several
users, so only the ratios of timings taken side by side (interleaved) in one run are
meaningful. {_cores_text(r)}*
{incomplete}
Issue 7's target: a vmapped batch of {r["batch"]} at least 2× cheaper per simulation than one
simulation, on this CPU. The honest comparison is against **the same solver run alone**: a
batch policy that also changes the solver mixes the solver's gain into the batch's.

**What is run.** Scene `{r["scene"]}`, t = 0 to {r["t_end"] * 1e3:g} ms with its default step
control ({_control_text(r["control"])}), {r["batch"]} cases
varying {", ".join(r["varied"])} by a log-normal spread s = {r["spread"]} around the defaults
(seed {r["seed"]}). This window is the start of the deployment (which locks at ≈ 0.54 s):
the panels leave rest half deployed with the journals centred in their bearings, so it holds
the pins' first flights across the clearance and their first impacts ({_density(r)};
docs/default_run.md gives the whole 2 s run's steps). A horizon this short
keeps the regeneration within ~40 min; the mechanisms of the cost below (idle cases, per-step
amortisation) do not depend on it, but the idle factor depends on how much the cases' step
counts differ, which a longer window may change. Every program is compiled ahead of time
(`jit(...).lower(...).compile()`); timings exclude compilation and are medians of
{done} interleaved repeat(s) (every row once per repeat, in turn).

**Columns.** *Speed-up per case*: the same solver's wall time alone over the policy's, both
for all {r["batch"]} cases (target ≥ 2); in brackets the same ratio of this process's CPU time
(less disturbed by other users' jobs); then the range of the ratio paired within each repeat.
A batch's cost splits into two measured factors, speed-up = per-step gain / idle:
**idle** = case-steps the batch's loop ran (each vmapped group iterates as often as its
slowest case, every case taking every iteration, masked once finished; counted from the
batch's own per-case step counts) over the steps the cases take alone; **per-step gain** =
time per step alone over time per case-step in the batch. *Policies*: `vmap all`, one vmap
over all cases; `groups of G`, vmapped groups of G consecutive cases run one after another in
one compiled program (`batch_function(group_size=G)`, `jax.lax.map(batch_size=G)`);
*oracle order*: the same groups over the cases sorted by their step count alone, which no
one knows before running them, so it is the bound on what any ordering can gain; `L lanes,
refilled`: L vmapped lanes, a lane that finishes its case taking the next one after at most
{r.get("segment_steps", 8)} steps (`batch_function(lanes=L)`, `jaxdeploy.lanes`), idle
counted by replaying that schedule from the per-case step counts; `2 cores`: see below.

## Results

{chr(10).join(sections)}
{_two_cores_text(r)}{_solver_comparison(r)}
## Why

{_why_summary(r)}

**Idle: a batch runs until its slowest case.** A vmapped adaptive run is one `while` loop;
each iteration costs every case of the batch, and the loop runs until the case with the most
steps finishes. Here the cases' step counts differ widely although their parameters differ by
only ~{r["spread"]:.0%}. How well the parameters predict a case's step count (rank
correlations below) says whether sorting the cases by a parameter could group like cases
together:

{_why(r)}

Smaller groups idle less (each stops at its own slowest case), and the oracle order makes
groups of nearly equal cases, which shows how much of the loss is idle steps.

**Per-step gain: what a batch amortises is per-operation overhead, not arithmetic.** On
XLA's CPU backend a step of one case is many small operations{size_text}; a batch turns each
into one operation over the batch, saving the dispatch and loop overhead of all but one, but
not the arithmetic per case. {_parts_reading(parts)} Inside a generalized-α step the Newton
`while` loop also runs until the last case of the batch has converged, and with modified
Newton the iteration matrix is formed for every case whenever any case asks for one
(`jaxdeploy.solvers.generalized_alpha._run_if`): work a case alone would not do, which the
per-step gain includes.

{parts_text}"""


if __name__ == "__main__":
    main()
