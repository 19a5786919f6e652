"""Design study: a concrete planar geometry for the reconstructed ``deploy_array`` mechanism.

Plain NumPy/SciPy/Matplotlib; it does not import jaxdeploy. It chooses and verifies the
geometry, mass properties, coil-spring drive and latch of the two-panel solar array of the seed
paper (Actuators 2024, 13(7), 274, Sections 3-4), whose mechanism figure (Fig. 8) and parameter
table (Table 2) are missing from our copy. See ``docs/deploy_array_geometry.md``.

Run from the repository root::

    .venv/bin/python experiments/deploy_array_geometry.py

It prints a table of every number and writes

* ``jaxdeploy/scenes/data/deploy_array_geometry.json``  (machine-readable scene definition),
* ``docs/figures/deploy_array_geometry_poses.png``         (mechanism at 45, 60, 75, 90 deg),
* ``docs/figures/deploy_array_geometry_conditioning.png``  (singular values, transmission angles),
* ``docs/figures/deploy_array_geometry_deployment.png``    (1-DOF deployment alpha(t)).

Conventions (also written into the JSON)
---------------------------------------
* SI units; angles in radians in the JSON (degrees only in printouts and labels).
* World frame: origin at the root hinge, +x along the deployed panels, +y along the stowed
  panel 1, z out of the plane. The spacecraft body (ground) occupies x < 0.
* Each moving body k has absolute coordinates q_k = (x_k, y_k, theta_k): its centre of mass and
  the angle from world +x to its body x-axis (counter-clockwise positive). The body frame origin
  is the centre of mass; attachment points are given in the body frame, so the world position of
  point s of body k is r_k + A(theta_k) s with A the 2-D rotation matrix.
* The ground ("body", the spacecraft) is fixed with q = (0, 0, 0): its points are world points.
* Deployment angle alpha = angle between panel 1 and +y = pi/2 - theta_panel1.
* A revolute joint between body i (point s_i) and body j (point s_j) contributes the two
  equations r_i + A_i s_i - r_j - A_j s_j = 0. Ten joints -> 20 equations, 21 coordinates.
* For a clearance joint, body i holds the bearing (hole) and body j the journal (pin).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402
from scipy.interpolate import CubicSpline  # noqa: E402

from jaxdeploy import pages  # noqa: E402  (only to record the commit: no model code)

ROOT = Path(__file__).resolve().parents[1]
JSON_PATH = ROOT / "jaxdeploy" / "scenes" / "data" / "deploy_array_geometry.json"
FIG_DIR = ROOT / "docs" / "figures"

DEG = np.pi / 180.0

# ---------------------------------------------------------------------------------------------
# 1. Design parameters
# ---------------------------------------------------------------------------------------------
# Panels: rigid honeycomb panels with cells, seen edge-on (the width is along z).
PANEL_LENGTH = 0.60  # m, hinge-to-hinge length of each panel (deployed span 1.2 m)
PANEL_WIDTH = 0.50  # m, out of plane (only used for the areal density)
PANEL_MASS = 1.20  # kg, 4.0 kg/m^2: Al honeycomb substrate + cells + harness + hinge brackets

# Support rods: Al tube 16 x 1.5 mm (0.19 kg/m) plus end fittings smeared along the rod.
ROD_MASS_PER_LENGTH = 0.20  # kg/m
ROD_FITTINGS_MASS = 0.05  # kg per rod (clevises / lugs)

# Geometry is specified in the DEPLOYED pose (alpha = 90 deg), in world coordinates: there both
# panels lie on the +x axis (panel 1 from 0 to L, panel 2 from L to 2L), so "deployed = panels
# along +x, panel 2 collinear with panel 1" holds by construction. Body-frame coordinates are
# derived from these below. Brackets on the panels sit a few cm below the panel mid-plane.
L = PANEL_LENGTH
DEPLOYED_POINTS = {
    # ground (spacecraft body, +x face at x = 0)
    "O": (0.0, 0.0),  # root hinge (panel 1 <-> body)
    "G4": (0.0, -0.300),  # rod 4 pivot on the body
    # four-bar body - panel 1 - rod 3 - rod 4
    "A": (0.365, -0.025),  # rod 3 bracket on panel 1
    "B": (0.465, -0.165),  # rod 3 <-> rod 4
    # rod 4 is a straight bar G4 -> B -> C with |G4 C| = 1.3 |G4 B|
    # dyad panel 2 + rod 5 between rod 4 (C) and the panel 1 tip hinge (H)
    "H": (L, 0.0),  # panel 1 <-> panel 2 hinge
    "D": (0.720, -0.040),  # rod 5 bracket on panel 2
    # bracing dyad rods 6, 7 between panel 1 (E) and panel 2 (F), knee K
    "E": (0.450, -0.020),
    "F": (0.810, -0.020),
    "K": (0.630, -0.260),
}
ROD4_EXTENSION = 1.3  # C = G4 + 1.3 (B - G4)

# Coil-spring drive at the root hinge: M(alpha) = k (alpha0 - alpha) drives alpha upwards.
SPRING_K = 1.5  # N m / rad
SPRING_ALPHA0 = 180.0 * DEG  # rad; zero-torque angle well beyond 90 deg -> preload at lock
ALPHA_START = 45.0 * DEG  # half-deployed state, at rest
ALPHA_LOCK = 90.0 * DEG  # latch engages

# Latch at alpha = 90 deg: stiff rotational spring-damper about the root hinge.
LATCH_TARGET_FREQ_HZ = 95.0  # the paper reports panel 2 vibrating mainly at 90-100 Hz
LATCH_DAMPING_RATIO = 0.05  # structural-joint damping of a latch (a few per cent)

# Joints: steel hinge pins of 5 mm radius; bearing radius = pin radius + radial clearance.
PIN_RADIUS = 0.005  # m
DEFAULT_CLEARANCE = 0.05e-3  # m, radial clearance c (the paper's middle value)
DEFAULT_RA = 1.6e-6  # m, the paper's typical roughness

# Sweep resolution, and the length used to make Jacobian columns dimensionless (half a panel).
SWEEP_STEP = 0.25 * DEG
SCALE_LENGTH = 0.30  # m

# ---------------------------------------------------------------------------------------------
# 2. Bodies and joints
# ---------------------------------------------------------------------------------------------
BODY_NAMES = ["panel1", "panel2", "rod3", "rod4", "rod5", "rod6", "rod7"]
NB = len(BODY_NAMES)
IDX = {name: k for k, name in enumerate(BODY_NAMES)}


def _p(name: str) -> np.ndarray:
    return np.asarray(DEPLOYED_POINTS[name], dtype=float)


def deployed_world_points() -> dict[str, np.ndarray]:
    pts = {k: _p(k) for k in DEPLOYED_POINTS}
    pts["C"] = pts["G4"] + ROD4_EXTENSION * (pts["B"] - pts["G4"])
    pts["T2"] = np.array([2.0 * L, 0.0])  # panel 2 tip
    return pts


def rot(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def build_model() -> tuple[dict, list[dict], np.ndarray]:
    """Bodies (mass, inertia, body-frame points), joints, and the deployed pose q90."""
    w = deployed_world_points()
    bodies: dict[str, dict] = {}
    q90 = np.zeros(3 * NB)

    def add_body(name, com, theta, length, mass, world_pts, kind):
        a = rot(theta).T
        # body-frame points, rounded to 1e-12 m (drops float noise; keeps the JSON clean)
        pts = {}
        for pn, pw in world_pts.items():
            s = a @ (pw - com)
            pts[pn] = np.round(s, 12) + 0.0
        bodies[name] = dict(
            kind=kind,
            length=float(length),
            mass=float(mass),
            inertia=float(mass * length**2 / 12.0),
            points=pts,
        )
        q90[3 * IDX[name] : 3 * IDX[name] + 3] = [com[0], com[1], theta]

    # Panels: centre of mass at mid-length, body x-axis from root hinge to tip.
    add_body(
        "panel1",
        np.array([L / 2, 0.0]),
        0.0,
        L,
        PANEL_MASS,
        {"root": w["O"], "tip": w["H"], "A": w["A"], "E": w["E"]},
        "panel",
    )
    add_body(
        "panel2",
        np.array([1.5 * L, 0.0]),
        0.0,
        L,
        PANEL_MASS,
        {"root": w["H"], "tip": w["T2"], "D": w["D"], "F": w["F"]},
        "panel",
    )

    # Rods: straight uniform bars, centre of mass at mid-length, body x-axis along the bar.
    def add_rod(name, p_from, p_to, named):
        vec = w[p_to] - w[p_from]
        length = np.linalg.norm(vec)
        mass = ROD_FITTINGS_MASS + ROD_MASS_PER_LENGTH * length
        com = 0.5 * (w[p_from] + w[p_to])
        add_body(name, com, np.arctan2(vec[1], vec[0]), length, mass, named, "rod")

    add_rod("rod3", "A", "B", {"A": w["A"], "B": w["B"]})
    add_rod("rod4", "G4", "C", {"G4": w["G4"], "B": w["B"], "C": w["C"]})
    add_rod("rod5", "C", "D", {"C": w["C"], "D": w["D"]})
    add_rod("rod6", "E", "K", {"E": w["E"], "K": w["K"]})
    add_rod("rod7", "K", "F", {"K": w["K"], "F": w["F"]})

    ground = {"O": w["O"], "G4": w["G4"]}
    bodies = {"ground": dict(kind="ground", points=ground), **bodies}

    # (name, body_i, point_i, body_j, point_j); for clearance joints i = bearing, j = journal.
    joint_table = [
        ("J1", "ground", "O", "panel1", "root", "root hinge (body - panel 1)"),
        ("J2", "panel1", "A", "rod3", "A", "four-bar: panel 1 - rod 3"),
        ("J3", "rod3", "B", "rod4", "B", "four-bar: rod 3 - rod 4"),
        ("J4", "ground", "G4", "rod4", "G4", "four-bar: rod 4 pivot on the body"),
        ("J5", "rod4", "C", "rod5", "C", "fold dyad: rod 4 - rod 5"),
        ("J6", "rod5", "D", "panel2", "D", "fold dyad: rod 5 - panel 2"),
        ("J7", "panel1", "tip", "panel2", "root", "panel hinge (panel 1 - panel 2)"),
        ("J8", "panel1", "E", "rod6", "E", "bracing dyad: panel 1 - rod 6"),
        ("J9", "rod6", "K", "rod7", "K", "bracing dyad: knee rod 6 - rod 7"),
        ("J10", "rod7", "F", "panel2", "F", "bracing dyad: rod 7 - panel 2"),
    ]
    joints = [
        dict(name=n, body_i=bi, point_i=pi, body_j=bj, point_j=pj, description=d)
        for n, bi, pi, bj, pj, d in joint_table
    ]
    return bodies, joints, q90


BODIES, JOINTS, Q90_DESIGN = build_model()

# ---------------------------------------------------------------------------------------------
# 3. Constraints
# ---------------------------------------------------------------------------------------------
DA = np.array([[0.0, -1.0], [1.0, 0.0]])  # d rot(theta)/d theta = rot(theta) @ DA


def body_state(q: np.ndarray, name: str) -> tuple[np.ndarray, float]:
    if name == "ground":
        return np.zeros(2), 0.0
    k = IDX[name]
    return q[3 * k : 3 * k + 2], q[3 * k + 2]


def world_point(q: np.ndarray, body: str, point: str) -> np.ndarray:
    r, th = body_state(q, body)
    return r + rot(th) @ BODIES[body]["points"][point]


def phi(q: np.ndarray) -> np.ndarray:
    """The 20 revolute constraint equations."""
    out = np.empty(2 * len(JOINTS))
    for m, j in enumerate(JOINTS):
        out[2 * m : 2 * m + 2] = world_point(q, j["body_i"], j["point_i"]) - world_point(
            q, j["body_j"], j["point_j"]
        )
    return out


def phi_q(q: np.ndarray) -> np.ndarray:
    """Analytic 20 x 21 constraint Jacobian."""
    jac = np.zeros((2 * len(JOINTS), 3 * NB))
    for m, j in enumerate(JOINTS):
        for body, point, sign in (
            (j["body_i"], j["point_i"], 1.0),
            (j["body_j"], j["point_j"], -1.0),
        ):
            if body == "ground":
                continue
            k = IDX[body]
            _, th = body_state(q, body)
            jac[2 * m : 2 * m + 2, 3 * k : 3 * k + 2] = sign * np.eye(2)
            jac[2 * m : 2 * m + 2, 3 * k + 2] = sign * rot(th) @ DA @ BODIES[body]["points"][point]
    return jac


I_TH1 = 3 * IDX["panel1"] + 2  # index of theta_panel1 in q


def alpha_of(q: np.ndarray) -> float:
    return np.pi / 2 - q[I_TH1]


def driven_phi(q: np.ndarray, alpha: float) -> np.ndarray:
    """20 joint equations + driving constraint theta_panel1 - (pi/2 - alpha) = 0."""
    return np.append(phi(q), q[I_TH1] - (np.pi / 2 - alpha))


def driven_jac(q: np.ndarray) -> np.ndarray:
    e = np.zeros(3 * NB)
    e[I_TH1] = 1.0
    return np.vstack([phi_q(q), e])


def newton(q: np.ndarray, alpha: float, tol: float = 1e-13, maxit: int = 50):
    """Newton-Raphson on the driven 21 x 21 system. Returns (q, iterations, residual)."""
    q = q.copy()
    for it in range(1, maxit + 1):
        res = driven_phi(q, alpha)
        dq = np.linalg.solve(driven_jac(q), -res)
        q += dq
        if np.max(np.abs(dq)) < tol:
            return q, it, float(np.max(np.abs(driven_phi(q, alpha))))
    raise RuntimeError(f"Newton did not converge at alpha = {alpha / DEG:.3f} deg")


def velocity_influence(q: np.ndarray) -> np.ndarray:
    """dq/dalpha from Phi_q v = 0 and d theta_1/d alpha = -1."""
    rhs = np.zeros(2 * len(JOINTS) + 1)
    rhs[-1] = -1.0
    return np.linalg.solve(driven_jac(q), rhs)


def mass_diag() -> np.ndarray:
    m = np.zeros(3 * NB)
    for name in BODY_NAMES:
        k = IDX[name]
        m[3 * k : 3 * k + 3] = [BODIES[name]["mass"], BODIES[name]["mass"], BODIES[name]["inertia"]]
    return m


def angle_between(u: np.ndarray, v: np.ndarray) -> float:
    c = u @ v / (np.linalg.norm(u) * np.linalg.norm(v))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def loop_angles(q: np.ndarray) -> dict[str, float]:
    """Transmission angles of the three loops (deg) plus the four-bar input angle."""
    P = {  # noqa: N806
        "O": np.zeros(2),
        "G4": BODIES["ground"]["points"]["G4"],
        "A": world_point(q, "panel1", "A"),
        "B": world_point(q, "rod4", "B"),
        "C": world_point(q, "rod4", "C"),
        "D": world_point(q, "panel2", "D"),
        "H": world_point(q, "panel1", "tip"),
        "E": world_point(q, "panel1", "E"),
        "F": world_point(q, "panel2", "F"),
        "K": world_point(q, "rod6", "K"),
    }
    return {
        # loop 1: angle at B between coupler (rod 3) and output rocker (rod 4)
        "mu1_fourbar_B": angle_between(P["A"] - P["B"], P["G4"] - P["B"]),
        # loop 2: angle at D between rod 5 and the panel-2 lever D -> H
        "mu2_fold_dyad_D": angle_between(P["C"] - P["D"], P["H"] - P["D"]),
        # loop 3: knee angle between rods 6 and 7
        "mu3_bracing_K": angle_between(P["E"] - P["K"], P["F"] - P["K"]),
        # input side of the four-bar: angle at A between panel 1 lever O -> A and rod 3
        "input_angle_A": angle_between(P["O"] - P["A"], P["B"] - P["A"]),
    }


def fold_angle(q: np.ndarray) -> float:
    """Relative angle of panel 2 w.r.t. panel 1, theta2 - theta1 (rad); 0 when collinear."""
    return q[3 * IDX["panel2"] + 2] - q[I_TH1]


# ---------------------------------------------------------------------------------------------
# 4. Assembly and continuation
# ---------------------------------------------------------------------------------------------
# A rough sketch of the half-deployed pose (alpha = 45 deg), read off a hand drawing: centres to
# about a centimetre, angles to a few degrees. Newton assembles the mechanism from it.
SKETCH_Q45 = {  # body: (x, y, theta_deg)
    "panel1": (0.21, 0.21, 45.0),
    "panel2": (0.62, 0.20, -50.0),
    "rod3": (0.29, 0.16, -80.0),
    "rod4": (0.20, -0.06, 50.0),
    "rod5": (0.44, 0.25, 60.0),
    "rod6": (0.36, 0.15, -80.0),
    "rod7": (0.46, 0.13, 55.0),
}


def sketch_q45() -> np.ndarray:
    q = np.zeros(3 * NB)
    for name, (x, y, th) in SKETCH_Q45.items():
        q[3 * IDX[name] : 3 * IDX[name] + 3] = [x, y, th * DEG]
    return q


def sweep() -> dict[str, np.ndarray]:
    q0 = sketch_q45()
    q45, iters, res = newton(q0, ALPHA_START)
    alphas = np.arange(ALPHA_START, ALPHA_LOCK + 0.5 * SWEEP_STEP, SWEEP_STEP)
    qs, iters_all = [q45], [iters]
    q = q45
    for a in alphas[1:]:
        qpred = q + velocity_influence(q) * SWEEP_STEP  # tangent predictor
        q, it, _ = newton(qpred, a)
        qs.append(q)
        iters_all.append(it)
    qs = np.array(qs)
    s_free, s_driven, s_scaled, cond, rank = [], [], [], [], []
    ang, fold, inertia, v_all = [], [], [], []
    mdiag = mass_diag()
    # Column scaling for a dimensionless check: theta columns divided by SCALE_LENGTH, i.e.
    # rotations measured as arc length at SCALE_LENGTH (all columns then in metres per metre).
    col_scale = np.tile([1.0, 1.0, 1.0 / SCALE_LENGTH], NB)
    for q in qs:
        sv = np.linalg.svd(phi_q(q), compute_uv=False)
        s_free.append(sv[-1])
        cond.append(sv[0] / sv[-1])
        rank.append(int(np.sum(sv > 1e-10 * sv[0])))
        s_driven.append(np.linalg.svd(driven_jac(q), compute_uv=False)[-1])
        s_scaled.append(np.linalg.svd(phi_q(q) * col_scale, compute_uv=False)[-1])
        ang.append(loop_angles(q))
        fold.append(fold_angle(q))
        v = velocity_influence(q)
        v_all.append(v)
        inertia.append(float(v @ (mdiag * v)))
    return dict(
        alpha=alphas,
        q=qs,
        q45_sketch=q0,
        newton_iters_assembly=iters,
        newton_residual_assembly=res,
        newton_iters_max_continuation=max(iters_all[1:]),
        sigma_free=np.array(s_free),
        sigma_driven=np.array(s_driven),
        sigma_scaled=np.array(s_scaled),
        cond=np.array(cond),
        rank=np.array(rank),
        angles={k: np.array([a[k] for a in ang]) for k in ang[0]},
        fold=np.array(fold),
        inertia=np.array(inertia),
        v=np.array(v_all),
    )


def robustness_of_assembly(q45: np.ndarray, n: int = 200, seed: int = 0) -> dict[str, float]:
    """Newton from n random perturbations of the sketch (+-3 cm, +-10 deg): same branch?"""
    rng = np.random.default_rng(seed)
    base = sketch_q45()
    same, converged = 0, 0
    for _ in range(n):
        pert = np.tile([0.03, 0.03, 10 * DEG], NB) * rng.uniform(-1, 1, 3 * NB)
        try:
            q, _, _ = newton(base + pert, ALPHA_START)
        except (RuntimeError, np.linalg.LinAlgError):
            continue
        converged += 1
        dq = q - q45
        dq[2::3] = (dq[2::3] + np.pi) % (2 * np.pi) - np.pi
        same += int(np.max(np.abs(dq)) < 1e-8)
    return dict(trials=n, converged=converged, same_branch=same)


# ---------------------------------------------------------------------------------------------
# 5. 1-DOF deployment dynamics with the configuration-dependent generalized inertia
# ---------------------------------------------------------------------------------------------
def spring_torque(alpha):
    return SPRING_K * (SPRING_ALPHA0 - alpha)


def deployment(sw: dict) -> dict:
    """I(a) a'' + 1/2 I'(a) a'^2 = M(a), from rest at 45 deg, until alpha = 90 deg."""
    spl = CubicSpline(sw["alpha"], sw["inertia"])
    dspl = spl.derivative()

    def rhs(_t, y):
        a, w = y
        a_c = np.clip(a, sw["alpha"][0], sw["alpha"][-1])
        return [w, (spring_torque(a) - 0.5 * dspl(a_c) * w**2) / spl(a_c)]

    def lock(_t, y):
        return y[0] - ALPHA_LOCK

    lock.terminal = True
    lock.direction = 1
    sol = solve_ivp(
        rhs, (0.0, 5.0), [ALPHA_START, 0.0], events=lock, rtol=1e-10, atol=1e-12, dense_output=True
    )
    t_lock = float(sol.t_events[0][0])
    w_lock = float(sol.y_events[0][0][1])
    # Energy check: 1/2 I(90) w^2 = spring work from 45 to 90 deg.
    work = SPRING_K * ((SPRING_ALPHA0 - ALPHA_START) ** 2 - (SPRING_ALPHA0 - ALPHA_LOCK) ** 2) / 2
    w_energy = float(np.sqrt(2 * work / spl(ALPHA_LOCK)))
    t = np.linspace(0.0, t_lock, 400)
    return dict(
        t_lock=t_lock,
        omega_lock=w_lock,
        omega_lock_energy=w_energy,
        spring_work=float(work),
        t=t,
        alpha_t=sol.sol(t)[0],
        omega_t=sol.sol(t)[1],
    )


# ---------------------------------------------------------------------------------------------
# 6. Latch and post-lock frequency
# ---------------------------------------------------------------------------------------------
def latch_design(sw: dict) -> dict:
    """Choose k_L so that the post-lock mode is at LATCH_TARGET_FREQ_HZ.

    With ideal joints and rigid bodies the locked mechanism keeps exactly one DOF (alpha),
    restrained by the latch spring (and, negligibly, the coil spring): a single mode with
    omega^2 = (k_L + k) / I(90 deg), I the generalized inertia. Its mode shape is dq/dalpha,
    so panel 2 vibrates at this frequency too; we report its tip motion per unit alpha.
    """
    i90 = float(sw["inertia"][-1])
    omega = 2 * np.pi * LATCH_TARGET_FREQ_HZ
    k_l = i90 * omega**2 - SPRING_K
    k_l = float(np.round(k_l, -3))  # round to 1 kN m/rad
    c_l = float(np.round(2 * LATCH_DAMPING_RATIO * np.sqrt((k_l + SPRING_K) * i90), 1))
    f_check = float(np.sqrt((k_l + SPRING_K) / i90) / (2 * np.pi))
    zeta = c_l / (2 * np.sqrt((k_l + SPRING_K) * i90))
    q90 = sw["q"][-1]
    v90 = sw["v"][-1]
    # Tip of panel 2 per unit alpha: r_tip' = r2' + dA/dtheta2 s_tip theta2'
    k2 = IDX["panel2"]
    s_tip = BODIES["panel2"]["points"]["tip"]
    dtip = v90[3 * k2 : 3 * k2 + 2] + rot(q90[3 * k2 + 2]) @ DA @ s_tip * v90[3 * k2 + 2]
    # Reduced modal check (constrained eigenproblem N^T K N x = w^2 N^T M N x with N = dq/da).
    static_offset = spring_torque(ALPHA_LOCK) / k_l
    return dict(
        k_latch=k_l,
        c_latch=c_l,
        damping_ratio=float(zeta),
        freq_hz=f_check,
        inertia_90=i90,
        panel2_tip_per_rad=dtip.tolist(),
        dfold_dalpha_90=float(v90[3 * k2 + 2] - v90[I_TH1]),
        static_offset_rad=float(static_offset),
    )


def hertz_estimate(clearance=DEFAULT_CLEARANCE, load=10.0) -> dict:
    """Linearized Hertz stiffness of a steel pin in its bearing, for the clearance-joint modes."""
    e, nu = 207e9, 0.3
    e_star = 1.0 / (2 * (1 - nu**2) / e)
    rj, rb = PIN_RADIUS, PIN_RADIUS + clearance
    r_star = rj * rb / (rb - rj)
    k_h = 4.0 / 3.0 * e_star * np.sqrt(r_star)
    delta = (load / k_h) ** (2.0 / 3.0)
    k_lin = 1.5 * k_h * np.sqrt(delta)
    f = np.sqrt(k_lin / PANEL_MASS) / (2 * np.pi)
    return dict(K=float(k_h), load=load, delta=float(delta), k_lin=float(k_lin), f_hz=float(f))


# ---------------------------------------------------------------------------------------------
# 7. Plots
# ---------------------------------------------------------------------------------------------
BODY_COLOURS = {
    "panel1": "tab:blue",
    "panel2": "tab:green",
    "rod3": "tab:red",
    "rod4": "tab:purple",
    "rod5": "tab:cyan",
    "rod6": "tab:orange",
    "rod7": "tab:brown",
}
BODY_LABELS = {
    "panel1": "panel 1",
    "panel2": "panel 2",
    "rod3": "rod 3",
    "rod4": "rod 4",
    "rod5": "rod 5",
    "rod6": "rod 6",
    "rod7": "rod 7",
}


ROD_LABEL_AT = {"rod3": 0.5, "rod4": 0.5, "rod5": 0.5, "rod6": 0.7, "rod7": 0.3}


def body_polyline(q: np.ndarray, name: str) -> np.ndarray:
    """World polyline used to draw a body: the bar, plus brackets for the panels."""
    pts = BODIES[name]["points"]
    if name.startswith("panel"):
        return np.array([world_point(q, name, "root"), world_point(q, name, "tip")])
    if name == "rod4":
        return np.array([world_point(q, name, p) for p in ("G4", "B", "C")])
    return np.array([world_point(q, name, p) for p in pts])


def plot_poses(sw: dict, path: Path) -> None:
    fig, axes = plt.subplots(2, 2, figsize=(14, 9.5), layout="constrained")
    for ax, a_deg in zip(axes.flat, (45, 60, 75, 90), strict=True):
        i = int(np.argmin(np.abs(sw["alpha"] - a_deg * DEG)))
        q = sw["q"][i]
        ax.add_patch(Rectangle((-0.25, -0.42), 0.25, 1.1, color="0.85", zorder=0))
        ax.text(-0.1, 0.3, "spacecraft\nbody\n(ground)", ha="center", va="center", fontsize=8)
        for name in BODY_NAMES:
            pl = body_polyline(q, name)
            panel = name.startswith("panel")
            ax.plot(
                pl[:, 0],
                pl[:, 1],
                "-",
                color=BODY_COLOURS[name],
                lw=4 if panel else 2,
                label=BODY_LABELS[name],
            )
            if panel:  # brackets: thin lines from the panel line to the off-plane attachment
                for p in BODIES[name]["points"]:
                    if p in ("root", "tip"):
                        continue
                    s = BODIES[name]["points"][p]
                    r, th = body_state(q, name)
                    foot = r + rot(th) @ np.array([s[0], 0.0])
                    wp = world_point(q, name, p)
                    ax.plot([foot[0], wp[0]], [foot[1], wp[1]], "-", color=BODY_COLOURS[name])
            if panel:  # panel name above the panel (the side without brackets)
                r, th = body_state(q, name)
                pos = r + 0.045 * (rot(th) @ np.array([0.0, 1.0]))
                ax.text(
                    *pos,
                    BODY_LABELS[name],
                    color=BODY_COLOURS[name],
                    fontsize=10,
                    fontweight="bold",
                    ha="center",
                    va="center",
                    rotation=np.degrees(th),
                )
            else:  # rod number in a box on the rod
                a, b = pl[0], pl[1]
                pos = a + ROD_LABEL_AT[name] * (b - a)
                ax.text(
                    *pos,
                    name[-1],
                    color=BODY_COLOURS[name],
                    fontsize=8,
                    fontweight="bold",
                    ha="center",
                    va="center",
                    zorder=4,
                    bbox=dict(boxstyle="circle,pad=0.15", fc="white", ec=BODY_COLOURS[name]),
                )
        for j in JOINTS:
            p = world_point(q, j["body_i"], j["point_i"])
            ax.plot(*p, "o", mfc="white", mec="k", ms=7, zorder=5)
            ax.annotate(
                j["name"], p, xytext=(4, 4), textcoords="offset points", fontsize=8, zorder=6
            )
        ang = loop_angles(q)
        fold_deg = round(float(np.degrees(fold_angle(q))), 1) + 0.0  # + 0.0 turns -0.0 into 0.0
        ax.set_title(
            f"alpha = {a_deg} deg, fold = {fold_deg:.1f} deg; "
            f"mu = {ang['mu1_fourbar_B']:.0f}/{ang['mu2_fold_dyad_D']:.0f}/"
            f"{ang['mu3_bracing_K']:.0f} deg",
            fontsize=10,
        )
        ax.set_xlim(-0.2, 1.25)
        ax.set_ylim(-0.36, 0.5)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=7, frameon=False)
    fig.suptitle(
        "deploy_array: reconstructed mechanism (joints J1..J10 numbered; 7 moving links, "
        "1 DOF)\nmu = transmission angles of loop 1 (at J3) / loop 2 (at J6) / loop 3 (at J9)"
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_conditioning(sw: dict, path: Path) -> None:
    a = np.degrees(sw["alpha"])
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.3))
    ax = axes[0]
    ax.plot(a, sw["sigma_free"], label=r"$\sigma_{min}(\Phi_q)$, 20x21")
    ax.plot(a, sw["sigma_driven"], label=r"$\sigma_{min}$ driven 21x21")
    ax.plot(
        a,
        sw["sigma_scaled"],
        "--",
        label=r"$\sigma_{min}(\Phi_q)$, $\theta$ columns / " + f"{SCALE_LENGTH} m",
    )
    ax.set_ylim(0, None)
    ax.set_xlabel("deployment angle alpha [deg]")
    ax.set_ylabel("smallest singular value")
    ax.set_title("Jacobian conditioning (rank 20 throughout)")
    ax.legend()
    ax.grid(alpha=0.3)
    ax = axes[1]
    labels = {
        "mu1_fourbar_B": "loop 1 four-bar, at J3 (rod 3/rod 4)",
        "mu2_fold_dyad_D": "loop 2 fold dyad, at J6 (rod 5/panel 2)",
        "mu3_bracing_K": "loop 3 bracing, at J9 (rod 6/rod 7)",
        "input_angle_A": "four-bar input side, at J2 (panel 1/rod 3)",
    }
    for k, lab in labels.items():
        ax.plot(a, sw["angles"][k], "--" if k == "input_angle_A" else "-", label=lab)
    ax.axhspan(0, 30, color="r", alpha=0.08)
    ax.axhspan(150, 180, color="r", alpha=0.08)
    ax.set_ylim(0, 180)
    ax.set_xlabel("deployment angle alpha [deg]")
    ax.set_ylabel("angle [deg]")
    ax.set_title("transmission angles (red: < 30 deg from dead centre)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax = axes[2]
    ax.plot(a, np.degrees(sw["fold"]), color="tab:green", label="panel 2 fold theta2-theta1 [deg]")
    ax.set_xlabel("deployment angle alpha [deg]")
    ax.set_ylabel("fold angle [deg]", color="tab:green")
    ax.grid(alpha=0.3)
    ax2 = ax.twinx()
    ax2.plot(a, sw["inertia"], color="k", label="generalized inertia I(alpha)")
    ax2.set_ylabel(r"I($\alpha$) [kg m$^2$]")
    ax2.set_ylim(0, None)
    ax.set_title("panel 2 fold and generalized inertia")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_deployment(dep: dict, path: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(dep["t"], np.degrees(dep["alpha_t"]), label="alpha [deg]")
    ax.axhline(90, color="0.5", ls=":")
    ax.axvline(dep["t_lock"], color="r", ls=":", label=f"lock at {dep['t_lock']:.3f} s")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("alpha [deg]")
    ax2 = ax.twinx()
    ax2.plot(dep["t"], dep["omega_t"], color="tab:orange", label="d alpha/dt [rad/s]")
    ax2.set_ylabel("d alpha/dt [rad/s]", color="tab:orange")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, loc="upper left")
    ax.set_title("1-DOF deployment, ideal joints, coil spring M = k (alpha0 - alpha)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# 8. Report and JSON
# ---------------------------------------------------------------------------------------------
def pose_dict(q: np.ndarray) -> dict[str, list[float]]:
    return {n: [float(v) for v in q[3 * IDX[n] : 3 * IDX[n] + 3]] for n in BODY_NAMES}


def write_json(sw, dep, latch, hz, robust, path: Path) -> None:
    bodies = {}
    for name, b in BODIES.items():
        entry = {"kind": b["kind"]}
        if name == "ground":
            entry["description"] = "spacecraft body, fixed; points in world coordinates"
        else:
            entry.update(
                mass=b["mass"],
                inertia=b["inertia"],
                length=b["length"],
                description="uniform thin "
                + ("plate seen edge-on" if b["kind"] == "panel" else "straight bar")
                + "; centre of mass at mid-length; inertia = mass * length**2 / 12 about the "
                "centre of mass (z axis)",
            )
        entry["points"] = {p: [float(v) for v in s] for p, s in b["points"].items()}
        bodies[name] = entry
    joints = []
    for j in JOINTS:
        d = dict(j)
        d["pin_radius"] = PIN_RADIUS
        d["default_clearance_joint"] = j["name"] in ("J1", "J7")
        if j["name"] == "J1":
            d["clearance_owner"] = "panel1"
        elif j["name"] == "J7":
            d["clearance_owner"] = "panel2"
        joints.append(d)
    i90 = len(sw["alpha"]) - 1
    ref = [int(np.argmin(np.abs(sw["alpha"] - a * DEG))) for a in range(45, 91, 5)]
    data = {
        "scene": "deploy_array",
        "source": "experiments/deploy_array_geometry.py (design study; reconstructed, the "
        "paper's Fig. 8 and Table 2 are missing)",
        "conventions": {
            "units": "SI (m, kg, s, N, rad)",
            "world_frame": "origin at the root hinge J1; +x along the deployed panels; +y along "
            "the stowed panel 1; spacecraft body at x < 0; planar, z out of plane",
            "coordinates": "q = [x, y, theta] per moving body, in the order of body_order; "
            "(x, y) = centre of mass, theta = angle from world +x to the body x-axis, CCW",
            "body_frame": "origin at the centre of mass; points are body-frame coordinates; "
            "world position = (x, y) + R(theta) @ point",
            "ground": "body 'ground' (the spacecraft) is fixed at q = (0, 0, 0); its points are "
            "world coordinates",
            "panel_axes": "panel body x-axis points from its root hinge to its tip",
            "deployment_angle": "alpha = pi/2 - theta_panel1 (angle between panel 1 and +y)",
            "fold_angle": "theta_panel2 - theta_panel1 (0 = collinear)",
            "revolute_joint": "r_i + R(theta_i) s_i - r_j - R(theta_j) s_j = 0 (2 equations)",
            "clearance_joint": "body_i holds the bearing (hole, radius pin_radius + c), body_j "
            "the journal (pin, radius pin_radius)",
            "gravity": "off (deploys in orbit); the ground is far heavier than the array",
        },
        "body_order": BODY_NAMES,
        "bodies": bodies,
        "joints": joints,
        "dof": 3 * NB - 2 * len(JOINTS),
        "initial_state": {
            "alpha": ALPHA_START,
            "q": sw["q"][0].tolist(),
            "q_by_body": pose_dict(sw["q"][0]),
            "qdot": [0.0] * (3 * NB),
            "note": "assembled by Newton (residual < 1e-12), at rest",
        },
        "deployed_state": {
            "alpha": float(sw["alpha"][i90]),
            "q": sw["q"][i90].tolist(),
            "q_by_body": pose_dict(sw["q"][i90]),
        },
        "reference_sweep": {
            "note": "ideal-joint kinematics every 5 deg, for tests of the scene: q by body_order, "
            "generalized inertia I(alpha) = (dq/dalpha)^T M (dq/dalpha), fold angle",
            "alpha": [float(sw["alpha"][i]) for i in ref],
            "q": [sw["q"][i].tolist() for i in ref],
            "generalized_inertia": [float(sw["inertia"][i]) for i in ref],
            "fold_angle": [float(sw["fold"][i]) for i in ref],
            "sigma_min_phi_q": [float(sw["sigma_free"][i]) for i in ref],
        },
        "coil_spring": {
            "joint": "J1",
            "law": "M(alpha) = k (alpha0 - alpha), M > 0 drives alpha up; generalized force on "
            "theta_panel1 is -M (reaction +M on the ground)",
            "k": SPRING_K,
            "alpha0": SPRING_ALPHA0,
            "torque_at_start": float(spring_torque(ALPHA_START)),
            "torque_at_lock": float(spring_torque(ALPHA_LOCK)),
        },
        "latch": {
            "joint": "J1",
            "engage_alpha": ALPHA_LOCK,
            "law": "once alpha first reaches engage_alpha, add M_L = -k_latch (alpha - "
            "engage_alpha) - c_latch alpha_dot (in the alpha sense; generalized force on "
            "theta_panel1 is -M_L), for the rest of the simulation",
            "k_latch": latch["k_latch"],
            "c_latch": latch["c_latch"],
            "damping_ratio": latch["damping_ratio"],
            "post_lock_frequency_hz": latch["freq_hz"],
        },
        "contact_defaults": {
            "pin_radius": PIN_RADIUS,
            "clearance": DEFAULT_CLEARANCE,
            "bearing_radius": PIN_RADIUS + DEFAULT_CLEARANCE,
            "Ra": DEFAULT_RA,
            "clearance_joints": {"J1": "panel1", "J7": "panel2"},
            "material": {"E": 207e9, "nu": 0.3},
        },
        "checks": {
            "sweep_step_deg": SWEEP_STEP / DEG,
            "rank_phi_q_min": int(sw["rank"].min()),
            "sigma_min_phi_q": float(sw["sigma_free"].min()),
            "sigma_min_driven": float(sw["sigma_driven"].min()),
            "sigma_min_phi_q_theta_columns_scaled": float(sw["sigma_scaled"].min()),
            "theta_column_scale_length": SCALE_LENGTH,
            "cond_phi_q_max": float(sw["cond"].max()),
            "transmission_angles_deg_min_max": {
                k: [float(v.min()), float(v.max())] for k, v in sw["angles"].items()
            },
            "fold_angle_at_start": float(sw["fold"][0]),
            "fold_angle_at_lock": float(sw["fold"][-1]),
            "generalized_inertia_start": float(sw["inertia"][0]),
            "generalized_inertia_lock": float(sw["inertia"][-1]),
            "generalized_inertia_max": float(sw["inertia"].max()),
            "lock_time_ideal_1dof": dep["t_lock"],
            "alpha_dot_at_lock": dep["omega_lock"],
            "panel2_tip_displacement_per_rad_alpha_at_lock": latch["panel2_tip_per_rad"],
            "assembly_robustness": robust,
        },
    }
    path.write_text(json.dumps(data, indent=2) + "\n")


def print_report(sw, dep, latch, hz, robust) -> None:
    line = "-" * 86
    print(line)
    print("deploy_array geometry study (world frame: root hinge at origin, deployed along +x)")
    print(line)
    print(f"{'body':8s} {'mass kg':>8s} {'J kg m2':>10s} {'len m':>7s}   points (body frame, m)")
    for name, b in BODIES.items():
        pts = ", ".join(f"{p}=({s[0]:+.4f},{s[1]:+.4f})" for p, s in b["points"].items())
        if name == "ground":
            print(f"{name:8s} {'-':>8s} {'-':>10s} {'-':>7s}   {pts}")
        else:
            print(f"{name:8s} {b['mass']:8.4f} {b['inertia']:10.3e} {b['length']:7.4f}   {pts}")
    print(line)
    print("joints (i = bearing side, j = journal side; pin radius 5 mm):")
    for j in JOINTS:
        print(
            f"  {j['name']:4s} {j['body_i']:>7s}.{j['point_i']:<5s} - "
            f"{j['body_j']:>7s}.{j['point_j']:<5s} {j['description']}"
        )
    print(line)
    print("poses q = (x, y, theta_deg):")
    for lab, q in (("alpha=45", sw["q"][0]), ("alpha=90", sw["q"][-1])):
        print(f"  {lab}:")
        for n in BODY_NAMES:
            x, y, th = q[3 * IDX[n] : 3 * IDX[n] + 3]
            print(f"    {n:7s} ({x:+.5f}, {y:+.5f}, {np.degrees(th):+9.4f})")
    print(line)
    print(
        f"assembly at 45 deg from the sketch: {sw['newton_iters_assembly']} Newton iterations, "
        f"residual {sw['newton_residual_assembly']:.1e}; continuation step "
        f"{SWEEP_STEP / DEG} deg, max {sw['newton_iters_max_continuation']} iterations/step"
    )
    print(
        f"robustness: {robust['converged']}/{robust['trials']} perturbed sketches converged, "
        f"{robust['same_branch']} to the same assembly branch"
    )
    dq = sw["q"][-1] - Q90_DESIGN
    print(f"max |q(90 deg) - designed deployed pose| = {np.max(np.abs(dq)):.2e}")
    print(
        f"rank Phi_q: min {sw['rank'].min()} (of 20); sigma_min(Phi_q) in "
        f"[{sw['sigma_free'].min():.4f}, {sw['sigma_free'].max():.4f}]; "
        f"sigma_min(driven) in [{sw['sigma_driven'].min():.4f}, {sw['sigma_driven'].max():.4f}]"
    )
    print(
        f"  cond(Phi_q) <= {sw['cond'].max():.1f}; sigma_min with theta columns / "
        f"{SCALE_LENGTH} m in [{sw['sigma_scaled'].min():.4f}, {sw['sigma_scaled'].max():.4f}]"
    )
    for k, v in sw["angles"].items():
        print(
            f"  {k:18s} {v[0]:6.1f} deg at 45 -> {v[-1]:6.1f} deg at 90, range "
            f"[{v.min():.1f}, {v.max():.1f}]"
        )
    print(
        f"fold angle theta2 - theta1: {np.degrees(sw['fold'][0]):.2f} deg at 45 -> "
        f"{np.degrees(sw['fold'][-1]):.2e} deg at 90"
    )
    k2 = IDX["panel2"]
    tip90 = world_point(sw["q"][-1], "panel2", "tip")
    tip45 = world_point(sw["q"][0], "panel2", "tip")
    print(
        f"panel 2 tip: ({tip45[0]:.4f}, {tip45[1]:.4f}) at 45 -> ({tip90[0]:.4f}, "
        f"{tip90[1]:.2e}) at 90; theta2(90) = {sw['q'][-1][3 * k2 + 2]:.1e} rad"
    )
    print(
        f"generalized inertia I(alpha): {sw['inertia'][0]:.4f} at 45, max "
        f"{sw['inertia'].max():.4f}, {sw['inertia'][-1]:.4f} kg m^2 at 90"
    )
    print(line)
    print(
        f"coil spring: k = {SPRING_K} N m/rad, alpha0 = {np.degrees(SPRING_ALPHA0):.0f} deg, "
        f"M(45) = {spring_torque(ALPHA_START):.3f}, M(90) = {spring_torque(ALPHA_LOCK):.3f} N m, "
        f"work 45->90 = {dep['spring_work']:.3f} J"
    )
    print(
        f"lock time {dep['t_lock']:.4f} s; alpha_dot at lock {dep['omega_lock']:.4f} rad/s "
        f"(energy check {dep['omega_lock_energy']:.4f})"
    )
    print(
        f"latch: k_L = {latch['k_latch']:.4g} N m/rad, c_L = {latch['c_latch']:.4g} N m s/rad "
        f"(zeta = {latch['damping_ratio']:.3f}); post-lock mode {latch['freq_hz']:.1f} Hz; "
        f"static offset {latch['static_offset_rad']:.1e} rad"
    )
    print(
        f"  mode shape at 90 deg: d fold/d alpha = {latch['dfold_dalpha_90']:.3f}, panel 2 tip "
        f"moves ({latch['panel2_tip_per_rad'][0]:+.3f}, {latch['panel2_tip_per_rad'][1]:+.3f}) "
        "m per rad of alpha"
    )
    print(
        f"  overshoot estimate alpha_dot/omega = "
        f"{dep['omega_lock'] / (2 * np.pi * latch['freq_hz']) / DEG:.3f} deg"
    )
    print(
        f"clearance joint (Hertz, c = {DEFAULT_CLEARANCE * 1e3} mm): K = {hz['K']:.3e} N/m^1.5; "
        f"at {hz['load']} N: delta = {hz['delta'] * 1e6:.3f} um, k = {hz['k_lin']:.3e} N/m, "
        f"panel mass on it: {hz['f_hz']:.0f} Hz"
    )
    print(line)


# What moves the numbers: this script alone (it uses none of jaxdeploy's model).
MEASURES = ["experiments/deploy_array_geometry.py"]


def main(argv=None) -> None:
    """The report, the figures and the page's block; the scene's data file only with
    `--write-data` (the assembly's Newton solves repeat only to round-off, and every
    deploy_array page measures that file: rewriting it at round-off would make them stale)."""
    write_data = "--write-data" in (sys.argv[1:] if argv is None else argv)
    record = pages.start(MEASURES, "python experiments/deploy_array_geometry.py")
    FIG_DIR.mkdir(parents=True, exist_ok=True)
    # Sanity: Gruebler count and consistency of the designed deployed pose.
    assert 3 * NB - 2 * len(JOINTS) == 1
    assert np.max(np.abs(phi(Q90_DESIGN))) < 1e-11
    sw = sweep()
    robust = robustness_of_assembly(sw["q"][0])
    dep = deployment(sw)
    latch = latch_design(sw)
    hz = hertz_estimate()
    print_report(sw, dep, latch, hz, robust)
    # Verification of the requirements of the brief.
    assert sw["rank"].min() == 20
    assert np.max(np.abs(sw["q"][-1] - Q90_DESIGN)) < 1e-9
    assert abs(sw["fold"][-1]) < 1e-9 and sw["fold"][0] < -60 * DEG
    assert min(np.minimum(v, 180 - v).min() for v in sw["angles"].values()) > 30
    assert 0.3 < dep["t_lock"] < 0.8
    plot_poses(sw, FIG_DIR / "deploy_array_geometry_poses.png")
    plot_conditioning(sw, FIG_DIR / "deploy_array_geometry_conditioning.png")
    plot_deployment(dep, FIG_DIR / "deploy_array_geometry_deployment.png")
    if write_data:
        write_json(sw, dep, latch, hz, robust, JSON_PATH)
    text = (
        "Made the figures `docs/figures/deploy_array_geometry_*.png`; the table below is its "
        f"printed report. `--write-data` also rewrites `{JSON_PATH.relative_to(ROOT)}`, the "
        "scene's definition (commit it on its own: every deploy_array page measures it)."
    )
    pages.write_block(str(ROOT / "docs" / "deploy_array_geometry.md"), "geometry", text, record)
    print(f"wrote 3 figures in {FIG_DIR.relative_to(ROOT)}" + (
        f" and {JSON_PATH.relative_to(ROOT)}" if write_data else ""))  # fmt: skip


if __name__ == "__main__":
    main()
