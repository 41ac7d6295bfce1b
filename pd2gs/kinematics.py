"""Joint type and parameters of one part from its Gaussian centres across states (paper App. A.3-A.4).

Frames: every joint is expressed in the world frame *at the reference state* (the ``start`` state of
``eval_states``, which is what rsart-eval reads; docs/evaluation.md). ``values`` are joint values per
state relative to the reference state (reference = 0): radians (revolute), scene units (prismatic).

Two joint-type rules, both always computed and reported:

* ``paper``: the residual matrix D (3 x n) of the part's motion between the reference state and the
  state farthest from it, with singular values s1 >= s2 >= s3, r = (s2 + s3) / s1 < 0.05 -> revolute.
  The paper calls D the Kabsch residual and argues "rank-1 for revolute, full rank for prismatic";
  after a full rigid (R, t) fit the residual of any rigid motion is pure noise, so the only reading
  under which that argument holds is the residual of the *translation-only* fit (R = I):
  D = (R - I)(P - p_mean) for a revolute part (near rank-1 for flat parts such as doors and lids,
  rank-2 for thick ones), noise (full rank) for a prismatic part. We use that reading, plus a noise
  guard (s1 below the noise floor -> nothing but translation -> prismatic).
* ``bic`` (ours): per-state translation fits vs per-state rigid fits over all states, compared by BIC
  with a noise floor.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rsart.metrics import joints as metric_joints

EPS = 1e-12


def kabsch(P: np.ndarray, Q: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid motion with Q ~ R P + t. P, Q: (n, 3); w: (n,) weights >= 0. -> R (3,3), t (3,)."""
    w = np.ones(len(P)) if w is None else np.asarray(w, dtype=np.float64)
    ws = w.sum() + EPS
    pc = (w[:, None] * P).sum(0) / ws
    qc = (w[:, None] * Q).sum(0) / ws
    H = ((P - pc) * w[:, None]).T @ (Q - qc)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, qc - R @ pc


@dataclass
class RigidFit:
    """Rigid motions from the reference state to every state: ``R`` (K, 3, 3), ``t`` (K, 3) (identity
    at the reference); ``inliers`` (n,) bool; ``rms`` residual RMS over inliers and states."""

    R: np.ndarray
    t: np.ndarray
    inliers: np.ndarray
    rms: float


def _residuals(P: np.ndarray, Qs: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(K, n) distances ||Q_k - (R_k P + t_k)||."""
    return np.linalg.norm(Qs - (np.einsum("kij,nj->kni", R, P) + t[:, None, :]), axis=2)


def robust_rigid(Qs: np.ndarray, ref: int, thresh: float, iters: int = 200, seed: int = 0) -> RigidFit:
    """RANSAC (3-point samples, one sample fits every state) + Kabsch re-fits on the inliers.

    Qs: (K, n, 3) the part's centres in every state; ``ref`` the reference state index; a point is an
    inlier when its residual is below ``thresh`` in every state.
    """
    K, n, _ = Qs.shape
    P = Qs[ref]
    rng = np.random.default_rng(seed)

    def fit(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Rs, ts = np.tile(np.eye(3), (K, 1, 1)), np.zeros((K, 3))
        for k in range(K):
            if k != ref:
                Rs[k], ts[k] = kabsch(P[mask], Qs[k][mask])
        return Rs, ts

    best = np.ones(n, dtype=bool)
    if n >= 6 and iters > 0:
        best_count = -1
        for _ in range(iters):
            idx = rng.choice(n, 3, replace=False)
            m = np.zeros(n, dtype=bool)
            m[idx] = True
            Rs, ts = fit(m)
            inl = (_residuals(P, Qs, Rs, ts) < thresh).all(axis=0)
            c = int(inl.sum())
            if c > best_count:
                best_count, best = c, inl
        if best.sum() < 3:
            best = np.ones(n, dtype=bool)
    Rs, ts = fit(best)
    for _ in range(3):  # re-fit on the consensus set, then re-select inliers
        inl = (_residuals(P, Qs, Rs, ts) < thresh).all(axis=0)
        if inl.sum() < 3:
            break
        best = inl
        Rs, ts = fit(best)
    res = _residuals(P, Qs, Rs, ts)[:, best]
    return RigidFit(Rs, ts, best, float(np.sqrt(np.mean(res ** 2))) if res.size else 0.0)


# ----------------------------------------------------------------------------- joint-type rules
def paper_ratio(P: np.ndarray, Q: np.ndarray) -> tuple[float, np.ndarray]:
    """r = (s2 + s3) / s1 of the translation-only residual D = Q - P - mean(Q - P); -> (r, singular values)."""
    D = (Q - P) - (Q - P).mean(0)
    s = np.linalg.svd(D.T, compute_uv=False)
    return float((s[1] + s[2]) / (s[0] + EPS)), s


def paper_rule(P: np.ndarray, Q: np.ndarray, r_thresh: float, noise: float) -> tuple[str, float]:
    """Paper's rule on two states -> (type, r); s1 under the noise floor sqrt(n)*noise means prismatic."""
    r, s = paper_ratio(P, Q)
    if s[0] < noise * math.sqrt(len(P)):
        return "prismatic", r
    return ("revolute" if r < r_thresh else "prismatic"), r


def bic_rule(P: np.ndarray, Qs: list[np.ndarray], fits: list[tuple[np.ndarray, np.ndarray]], noise: float
             ) -> tuple[str, float, float]:
    """Ours: BIC of a translation model vs a rotation model over every non-reference state.

    P: (n, 3) reference centres; Qs: the other states' centres; fits: their (R, t) from P.
    The parameter counts are those of the fits whose RSS is used: a free translation per state (3 each)
    vs a free rigid motion per state (6 each); the rigid model nests the translation model, so it must
    buy its 3 extra parameters per state with a real drop in RSS (measured: counting only the joint's
    own parameters, 4 + K-1 vs 2 + K-1, let 4 mm noise turn a drawer revolute).
    sigma^2 = max(RSS / n_obs, noise^2). -> (type, BIC_revolute, BIC_prismatic).
    """
    rss_t = sum(float(np.sum(((Q - P) - (Q - P).mean(0)) ** 2)) for Q in Qs)
    rss_r = sum(float(np.sum((Q - (P @ R.T + t)) ** 2)) for Q, (R, t) in zip(Qs, fits))
    n_obs = 3 * len(P) * len(Qs)
    m = len(Qs)
    def bic(rss: float, k: int) -> float:
        return n_obs * math.log(max(rss / n_obs, noise ** 2)) + k * math.log(n_obs)
    b_rev, b_pri = bic(rss_r, 6 * m), bic(rss_t, 3 * m)
    return ("revolute" if b_rev < b_pri else "prismatic"), b_rev, b_pri


# ----------------------------------------------------------------------------- parameters
def rotation_axis_angle(R: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit axis u (eigenvector of R with eigenvalue 1) and angle in [0, pi] with R = Rot(u, angle)."""
    w, V = np.linalg.eig(R)
    u = np.real(V[:, int(np.argmin(np.abs(w - 1.0)))])
    u = u / (np.linalg.norm(u) + EPS)
    vee = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if float(u @ vee) < 0:
        u = -u
    angle = math.acos(float(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))
    return u, angle


def signed_angle(R: np.ndarray, u: np.ndarray) -> float:
    """Angle of R about the fixed unit axis u (atan2 of the skew part along u and the trace)."""
    vee = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return math.atan2(0.5 * float(u @ vee), (np.trace(R) - 1) / 2)


def revolute_params(Rs: list[np.ndarray], ts: list[np.ndarray], centroid: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """Axis, pivot (point on the axis closest to ``centroid``) and angles of motions x -> R_k x + t_k.

    The axis comes from the largest rotation; the pivot solves the stacked rank-2 systems
    (I - R_k) x = t_k by least squares (minimum norm), then slides along the axis to the centroid.
    """
    angles = [rotation_axis_angle(R)[1] for R in Rs]
    u, _ = rotation_axis_angle(Rs[int(np.argmax(angles))])
    A = np.concatenate([np.eye(3) - R for R in Rs])
    b = np.concatenate(ts)
    x0 = np.linalg.lstsq(A, b, rcond=1e-8)[0]
    pivot = x0 + u * float(u @ (centroid - x0))
    return u, pivot, [signed_angle(R, u) for R in Rs]


def prismatic_params(ts: list[np.ndarray]) -> tuple[np.ndarray, list[float]]:
    """Unit axis (principal direction of the translations t_k) and distances t_k . axis."""
    T = np.stack(ts)
    big = T[int(np.argmax(np.linalg.norm(T, axis=1)))]
    if len(T) == 1:
        a = big / (np.linalg.norm(big) + EPS)
    else:
        a = np.linalg.svd(T, full_matrices=False)[2][0]
        if float(a @ big) < 0:
            a = -a
    return a, [float(t @ a) for t in T]


@dataclass
class JointFit:
    """One part's fitted joint: ``type`` chosen by ``rule``; both rules' verdicts kept in ``diagnostics``.

    The joint estimate itself is rsart's :class:`rsart.metrics.JointEstimate` (:meth:`estimate`), the one
    record the metrics compare; this fit adds the per-state values and how the type was chosen.

    axis (3,) unit, origin (3,) point on the axis, world frame at the reference state;
    values: state id -> value relative to the reference state (rad | scene units).
    """

    type: str
    axis: np.ndarray
    origin: np.ndarray
    values: dict[str, float]
    rule: str
    type_paper: str
    type_bic: str
    diagnostics: dict = field(default_factory=dict)

    def estimate(self, start: str, end: str) -> metric_joints.JointEstimate:
        """The joint as the metrics see it: ``delta`` = value[end] - value[start]."""
        return metric_joints.JointEstimate.make(self.type, self.axis, self.origin, self.values[end] - self.values[start])

    def to_submission(self) -> dict:
        return {"type": self.type, "axis": [float(x) for x in self.axis],
                "origin": [float(x) for x in self.origin], "values": {k: float(v) for k, v in self.values.items()}}


#: The old name of :class:`JointFit`, kept while ``articulate.py`` (rewritten under its own issue) uses it.
JointEstimate = JointFit


def estimate_joint(Qs: np.ndarray, state_ids: list[str], ref: str, end: str | None = None, rule: str = "paper",
                   r_thresh: float = 0.05, noise_rel: float = 1e-3, thresh_rel: float = 0.02,
                   iters: int = 200, seed: int = 0) -> JointFit:
    """Estimate one part's joint from its centres Qs (K, n, 3) in the states ``state_ids``.

    ``ref``: reference (start) state; ``end``: the state whose value is made positive by the axis sign
    (default: the state farthest from ``ref``). Thresholds are fractions of the part's extent.
    """
    K = len(state_ids)
    r = state_ids.index(ref)
    extent = float(np.linalg.norm(np.ptp(Qs[r], axis=0))) or 1.0
    fit = robust_rigid(Qs, r, thresh_rel * extent, iters, seed)
    m = fit.inliers
    P = Qs[r][m]
    others = [k for k in range(K) if k != r]
    disp = {k: float(np.mean(np.linalg.norm(Qs[k][m] - P, axis=1))) for k in others}
    far = max(others, key=lambda k: disp[k])
    t_paper, ratio = paper_rule(P, Qs[far][m], r_thresh, noise_rel * extent)
    fits = [(fit.R[k], fit.t[k]) for k in others]
    t_bic, b_rev, b_pri = bic_rule(P, [Qs[k][m] for k in others], fits, noise_rel * extent)
    jtype = t_paper if rule == "paper" else t_bic
    centroid = P.mean(0)
    if jtype == "revolute":
        axis, origin, vals = revolute_params([fit.R[k] for k in others], [fit.t[k] for k in others], centroid)
    else:
        axis, vals = prismatic_params([(Qs[k][m] - P).mean(0) for k in others])
        origin = centroid
    values = {state_ids[r]: 0.0}
    values.update({state_ids[k]: v for k, v in zip(others, vals)})
    sign_state = end if end in values and end != ref else state_ids[far]
    if values[sign_state] < 0:
        axis = -axis
        values = {k: -v for k, v in values.items()}
    diag = {"paper_r": ratio, "bic_revolute": b_rev, "bic_prismatic": b_pri, "inlier_frac": float(m.mean()),
            "rigid_rms": fit.rms, "n": int(len(m)), "far_state": state_ids[far]}
    return JointFit(jtype, axis, origin, values, rule, t_paper, t_bic, diag)
