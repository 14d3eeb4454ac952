"""The text of a Robotarium controller: each law's terms as standalone numpy, and the main loop.

Code generation necessarily writes each formula a second time: the script that
:func:`formationlab.io.robotarium.robotarium_script` writes runs on the Robotarium, where
formationlab is not installed, so it cannot call :mod:`formationlab.controllers.kinds`. The
formulas here are the same equations in plain numpy over lists of edges and triples, each
line with its equation; ``tests/test_robotarium.py`` holds the script's law against the
package's (``Law.control``) on random states, for every law the export writes, so the two
cannot drift apart.

Each block is a function of the script (``p``: the law's points ``(N, 2)``; ``u``: their
velocities ``(N, 2)``, added to in place) that reads only the literal constants written at
the top of the script. :data:`TERMS` names the blocks; :func:`law_function` composes them.
"""

from __future__ import annotations

__all__ = ["MAIN", "TERMS", "law_function"]

#: the edge term of the paper's distance law (eqs. 5, 7, 8) and Khatib's repulsion
LOG_BARRIER = '''

def edge_terms(p, u):
    """-K_EDGE grad_i phi_ij of every edge, phi of eq. (5) (eq. 8)."""
    r_vec = p[J] - p[I]                                # r_ij = q_j - q_i
    r = np.linalg.norm(r_vec, axis=1)
    slope = (r - D) / ((D - A) * (r - A))              # phi'(r) = 1/(d - a) - 1/(r - a), eq. (7)
    f = (K_EDGE * slope / r)[:, None] * r_vec          # -K_EDGE grad_i phi_ij, eq. (8)
    np.add.at(u, I, f)
    np.add.at(u, J, -f)
'''

SQUARED = '''

def edge_terms(p, u):
    """-K_EDGE grad_i of 1/4 (r_ij^2 - d_ij^2)^2 over the edges (Krick et al. 2009)."""
    r_vec = p[J] - p[I]                                # r_ij = q_j - q_i
    r2 = np.sum(r_vec * r_vec, axis=1)
    f = (K_EDGE * (r2 - D * D))[:, None] * r_vec       # k (r_ij^2 - d_ij^2) r_ij
    np.add.at(u, I, f)
    np.add.at(u, J, -f)
'''

BEARING = '''

def edge_terms(p, u):
    """-K_EDGE P_(g_ij) g*_ij of every edge (Zhao and Zelazo 2016, eq. 11)."""
    r_vec = p[J] - p[I]                                # e_ij = p_j - p_i
    g = r_vec / np.linalg.norm(r_vec, axis=1)[:, None] # g_ij, the measured bearing
    along = np.sum(g * BEARINGS, axis=1)[:, None]
    f = -K_EDGE * (BEARINGS - g * along)               # -k P_(g_ij) g*_ij, their eq. (11)
    np.add.at(u, I, f)
    np.add.at(u, J, -f)
'''

REPULSION = '''

def repulsion_terms(p, u):
    """Khatib's repulsion gamma_ij between robots that are not neighbours (the gamma_ij of
    eq. 8): gamma = ETA/2 (1/s - 1/S0)^2 for a clearance s = r_ij - a_ij below S0."""
    r_vec = p[PJ] - p[PI]
    r = np.linalg.norm(r_vec, axis=1)
    s = r - PA
    near = s < S0
    slope = np.where(near, -ETA * (1.0 / s - 1.0 / S0) / s**2, 0.0)  # gamma'(s)
    f = (K_REPULSION * slope / r)[:, None] * r_vec     # -K_REPULSION grad_i gamma_ij
    np.add.at(u, PI, f)
    np.add.at(u, PJ, -f)
'''

RESTRICTION = '''

def restriction_terms(p, u):
    """-K_A grad_i psi_i of the restricted triples (eqs. 11, 13, 14, 23)."""
    r_ij = p[TJ] - p[TI]
    r_ik = p[TK] - p[TI]
    c = r_ij[:, 0] * r_ik[:, 1] - r_ij[:, 1] * r_ik[:, 0]  # c_ijk = (r_ij x r_ik) . k
    on = (ALPHA * c + THETA >= 0.0)                    # Upsilon(alpha c + theta), eq. (14)
    w = 2.0 * K_A * ALPHA * on                         # (i, j, k) and (i, k, j) alike, eq. (13)
    r_jk = p[TK] - p[TJ]
    f = np.column_stack([w * r_jk[:, 1], -w * r_jk[:, 0]])  # -w k x r_jk, eq. (23)
    np.add.at(u, TI, f)
'''

AREA = '''

def area_terms(p, u):
    """-K_AREA grad of 1/2 (A_abc - A*_abc)^2 of each triangle, A = c_abc / 2
    (Anderson et al. 2017; grad_a A_abc = 1/2 k x r_bc, the paper's eq. 23 halved)."""
    pa, pb, pc = p[AA], p[AB], p[AC]
    ab, ac = pb - pa, pc - pa
    c = ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0]      # c_abc = 2 A_abc
    g = K_AREA * 0.5 * (0.5 * c - AREA_TARGET)         # K_AREA (A - A*) / 2
    for a, q1, q2 in ((AA, pb, pc), (AB, pc, pa), (AC, pa, pb)):  # a's term: -g k x r_(q1 q2)
        np.add.at(u, a, np.column_stack([g * (q2[:, 1] - q1[:, 1]), -g * (q2[:, 0] - q1[:, 0])]))
'''

#: the blocks by name, in the order the law adds them
TERMS = {
    "log-barrier": LOG_BARRIER,
    "squared": SQUARED,
    "bearing": BEARING,
    "repulsion": REPULSION,
    "restriction": RESTRICTION,
    "area": AREA,
}

_CALLS = {
    "repulsion": "repulsion_terms(p, u)",
    "restriction": "restriction_terms(p, u)",
    "area": "area_terms(p, u)",
}


def law_function(edge: str, extra: tuple[str, ...], equation: str) -> str:
    """The blocks of the edge term ``edge`` and the ``extra`` terms, and ``law(p)`` that
    adds them (``equation``: what the docstring of ``law`` cites)."""
    calls = ["edge_terms(p, u)", *(_CALLS[e] for e in extra)]
    body = "\n".join(f"    {c}" for c in calls)
    blocks = "".join(TERMS[k] for k in (edge, *extra))
    return (
        f"{blocks}\n\ndef law(p):\n"
        f'    """The single-integrator velocities u (N, 2) of the points p (N, 2):\n'
        f'    {equation}."""\n'
        f"    u = np.zeros_like(p)\n{body}\n    return u\n"
    )


#: the Robotarium's loop: the law on the points, the Robotarium's barrier certificate and its
#: map to unicycles, the wheels' limit, and the stop rule
MAIN = '''

def distance_errors(p):
    """|r_ij - d_ij| of every edge, metres."""
    return np.abs(np.linalg.norm(p[J] - p[I], axis=1) - D)


def formation_reached(p):
    """Whether the points p (N, 2) hold the formation: REACHED_BY says what is judged."""
    ok = True
    if "distances" in REACHED_BY:
        ok = ok and np.max(distance_errors(p)) <= TOLERANCE
    if "orientation" in REACHED_BY:                    # sign(c_ijk) = -sign(alpha_ijk), eq. (14)
        r_ij, r_ik = p[TJ] - p[TI], p[TK] - p[TI]
        c = r_ij[:, 0] * r_ik[:, 1] - r_ij[:, 1] * r_ik[:, 0]
        ok = ok and bool(np.all(ALPHA * c < 0.0))
    if "bearings" in REACHED_BY:                       # |g_ij - g*_ij| within TOLERANCE / d_ij
        g = (p[J] - p[I]) / np.linalg.norm(p[J] - p[I], axis=1)[:, None]
        ok = ok and bool(np.all(np.linalg.norm(g - BEARINGS, axis=1) * D <= TOLERANCE))
    return bool(ok)


def unicycle_factor(dxu):
    """Each robot's factor min(1, MAX_SPEED / |v|, MAX_TURN_RATE / |omega|) for its (v, omega)
    (2, N): scaled by it, the path keeps its curvature and the point its direction."""
    return np.minimum(1.0, np.minimum(MAX_SPEED / np.maximum(np.abs(dxu[0]), 1e-300),
                                      MAX_TURN_RATE / np.maximum(np.abs(dxu[1]), 1e-300)))


def main(save_poses=None):
    """Run the formation on the Robotarium; with save_poses, write the poses of every step
    to that .npz file (poses (steps + 1, 3, N), reached, steps)."""
    r = robotarium.Robotarium(number_of_robots=N, show_figure=SHOW_FIGURE,
                              initial_conditions=INITIAL_POSES.copy(),
                              sim_in_real_time=SIM_IN_REAL_TIME)
    si_barrier = create_single_integrator_barrier_certificate_with_boundary(
        barrier_gain=BARRIER_GAIN, safety_radius=SAFETY_RADIUS,
        magnitude_limit=MAX_WHEEL_SPEED)
    # the map's own turn cap clips omega alone (turning the point's velocity); the cap is
    # unicycle_factor's instead, which scales v and omega together
    si_to_uni_dyn, uni_to_si_states = create_si_to_uni_mapping(
        projection_distance=PROJECTION_DISTANCE, angular_velocity_limit=np.inf)
    poses = [np.array(r.get_poses(), dtype=float)]
    reached = False
    steps = 0
    while steps < MAX_STEPS:
        x = poses[-1]
        p = uni_to_si_states(x).T                      # the points the law moves, (N, 2)
        if formation_reached(p):
            reached = True
            break
        dxi = law(p).T                                 # single-integrator velocities, (2, N)
        dxi = dxi * unicycle_factor(si_to_uni_dyn(dxi, x))  # each robot within its limits
        dxi = si_barrier(dxi, p.T)                     # the certificate's QP
        dxu = si_to_uni_dyn(dxi, x)                    # (v, omega) of each robot
        # where the certificate sped a robot up past its limits, every robot slows by the
        # same factor: the certificate's inequalities hold for any common factor <= 1
        dxu = dxu * np.min(unicycle_factor(dxu))
        r.set_velocities(np.arange(N), dxu)
        r.step()
        steps += 1
        poses.append(np.array(r.get_poses(), dtype=float))
    print("formation reached after %d steps (%.1f s)" % (steps, steps * TIME_STEP) if reached
          else "formation not reached within %d steps" % MAX_STEPS)
    if save_poses:
        np.savez(save_poses, poses=np.array(poses), reached=reached, steps=steps)
    r.call_at_scripts_end()


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--save-poses") + 1] if "--save-poses" in sys.argv else None)
'''
