"""How many movable parts: pluggable counters (paper Sec. 3.3 asks a VLM; we add a motion counter).

* ``trajectory`` (default): k-means on per-Gaussian local rigid motions, k chosen by silhouette
  (:func:`count_by_trajectories`).
* ``motion``: sequential RANSAC of rigid motions on the dynamic Gaussians' centres across all
  states; every rigid motion supported by at least ``min_frac`` of them counts as one part.
* ``vlm``: the paper's query to an OpenAI-compatible chat-completions endpoint on M image pairs of
  different states; the answer is the mode of the parsed counts (ties -> the smaller count).
* ``given``: the true count (oracle ablation).
"""
from __future__ import annotations

import base64
import io
import json
import os
import re
import urllib.error
import urllib.request
from collections import Counter
from dataclasses import dataclass

import numpy as np
from PIL import Image
from scipy.spatial import cKDTree

from rsart.errors import RsartError

from pd2gs.kinematics import kabsch

PROMPT = ("Compare the two images. How many components moved? "
          "Answer: 'Number of moved components: [N]'.")
_ANSWER = re.compile(r"number\s+of\s+moved\s+components\s*:\s*\[?\s*(\d+)\s*\]?", re.IGNORECASE)


class CountError(RsartError, RuntimeError):
    """The part count could not be determined (message says why)."""


# ----------------------------------------------------------------------------- motion counter
@dataclass
class MotionCount:
    """``n`` rigid motions found; ``support`` (n,) their inlier counts; ``labels`` (N_dyn,) 1..n, 0 = none."""

    n: int
    support: list[int]
    labels: np.ndarray


def _rigid_inliers(Qs: np.ndarray, idx: np.ndarray, thresh: float) -> np.ndarray:
    """(n,) bool: points whose residual under the rigid motions fitted to ``idx`` is < thresh in every state."""
    P = Qs[0]
    ok = np.ones(P.shape[0], dtype=bool)
    for k in range(1, Qs.shape[0]):
        R, t = kabsch(P[idx], Qs[k][idx])
        ok &= np.linalg.norm(Qs[k] - (P @ R.T + t), axis=1) < thresh
    return ok


def count_rigid_motions(means_dyn: np.ndarray, thresh: float, min_frac: float = 0.05, max_parts: int = 8,
                        iters: int = 300, seed: int = 0, neighbours: int = 32) -> MotionCount:
    """Sequential RANSAC over rigid motions of ``means_dyn`` (K, n, 3).

    Minimal samples are a random point and two of its ``neighbours`` nearest neighbours (state 0), which
    makes a sample lie on one part far more often than three uniform draws. The best model's inliers
    (re-fitted twice) are removed and the search repeats while a model keeps >= min_frac of n.
    """
    K, n, _ = means_dyn.shape
    rng = np.random.default_rng(seed)
    labels = np.zeros(n, dtype=np.int64)
    remaining = np.arange(n)
    support: list[int] = []
    while len(support) < max_parts and len(remaining) >= max(3, min_frac * n):
        Q = means_dyn[:, remaining]
        tree = cKDTree(Q[0])
        kq = min(neighbours, len(remaining))
        best = np.zeros(len(remaining), dtype=bool)
        for _ in range(iters):
            i = rng.integers(len(remaining))
            _, nb = tree.query(Q[0][i], k=kq)
            nb = np.atleast_1d(nb)[1:]
            if len(nb) < 2:
                break
            idx = np.concatenate([[i], rng.choice(nb, 2, replace=False)])
            inl = _rigid_inliers(Q, idx, thresh)
            if inl.sum() > best.sum():
                best = inl
        for _ in range(2):
            if best.sum() < 3:
                break
            best = _rigid_inliers(Q, np.flatnonzero(best), thresh)
        if best.sum() < min_frac * n:
            break
        support.append(int(best.sum()))
        labels[remaining[best]] = len(support)
        remaining = remaining[~best]
    return MotionCount(len(support), support, labels)


def local_rigid_motions(means: np.ndarray, neighbours: int = 16, sample: int = 1500, seed: int = 0,
                        return_index: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """(M, 6) per-Gaussian rigid motion first -> last state, fitted (Kabsch) on each sampled Gaussian's
    ``neighbours`` nearest neighbours in the first state: [rotation vector (rad), translation / extent].

    A rigid part has one (R, t) for all its points, so these features form one tight cluster per part
    (unlike raw trajectories, whose directions vary across a rotating part). ``means``: (K, N, 3).
    ``return_index``: also return the (M,) indices of the Gaussians the rows belong to.
    """
    from scipy.spatial.transform import Rotation

    K, n, _ = means.shape
    rng = np.random.default_rng(seed)
    idx = np.arange(n) if n <= sample else rng.choice(n, sample, replace=False)
    P, Q = means[0], means[-1]
    extent = float(np.linalg.norm(np.ptp(P, axis=0))) + 1e-12
    _, nb = cKDTree(P).query(P[idx], k=min(neighbours, n))
    feats = np.empty((len(idx), 6))
    resid = np.empty(len(idx))
    for r, ns in enumerate(np.atleast_2d(nb)):
        R, t = kabsch(P[ns], Q[ns])
        feats[r, :3] = Rotation.from_matrix(R).as_rotvec()
        feats[r, 3:] = t / extent
        resid[r] = np.sqrt(np.mean(np.sum((P[ns] @ R.T + t - Q[ns]) ** 2, axis=1)))
    # neighbourhoods straddling two parts fit no rigid motion well: drop them (they would form a
    # spurious "in-between" cluster)
    keep = resid <= 2.0 * np.median(resid) + 1e-9
    return (feats[keep], idx[keep]) if return_index else feats[keep]


def count_by_trajectories(features: np.ndarray, max_parts: int = 8, min_silhouette: float = 0.35,
                          seed: int = 0) -> tuple[int, dict]:
    """Number of distinct rigid motions by model selection over k (ours; the default counter).

    k-means (k-means++) on per-Gaussian local rigid motions (:func:`local_rigid_motions`) for
    k = 2..max_parts; the k with the best silhouette wins if it reaches ``min_silhouette``, else 1.
    Robust to trained fields whose per-part motion is not exactly rigid, where the sequential-RANSAC
    counter finds nothing or over-splits. Returns (n, {"silhouettes": {k: s}}).
    """
    from sklearn.cluster import KMeans
    from sklearn.metrics import silhouette_score

    n = len(features)
    if n < 10:
        return (1 if n else 0), {"silhouettes": {}}
    scores = {}
    for k in range(2, min(max_parts, n - 1) + 1):
        lab = KMeans(k, n_init=4, random_state=seed).fit_predict(features)
        if len(np.unique(lab)) < 2:
            continue
        scores[k] = float(silhouette_score(features, lab, random_state=seed))
    best = max(scores, key=scores.get) if scores else 1
    return (best if scores and scores[best] >= min_silhouette else 1), {"silhouettes": scores}


# ----------------------------------------------------------------------------- VLM counter
def parse_count(text: str) -> int | None:
    """The N of "Number of moved components: [N]" (brackets optional, case-insensitive), else None."""
    m = _ANSWER.search(text or "")
    return int(m.group(1)) if m else None


def mode_count(counts: list[int | None]) -> int:
    """Most frequent parsed count (ties -> the smaller); CountError when no answer parsed."""
    valid = [c for c in counts if c is not None]
    if not valid:
        raise CountError(f"no parsable VLM answer among {len(counts)} (expected 'Number of moved components: [N]')")
    freq = Counter(valid)
    top = max(freq.values())
    return min(c for c, f in freq.items() if f == top)


def png_data_url(rgb: np.ndarray) -> str:
    """(H, W, 3) uint8 image -> 'data:image/png;base64,...'."""
    buf = io.BytesIO()
    Image.fromarray(np.asarray(rgb, dtype=np.uint8)).save(buf, format="PNG")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def vlm_request(img_a: np.ndarray, img_b: np.ndarray, model: str) -> dict:
    """The chat-completions request body: the paper's prompt and the two images as data URLs."""
    return {"model": model, "temperature": 0,
            "messages": [{"role": "user", "content": [
                {"type": "text", "text": PROMPT},
                {"type": "image_url", "image_url": {"url": png_data_url(img_a)}},
                {"type": "image_url", "image_url": {"url": png_data_url(img_b)}}]}]}


def ask_vlm(url: str, img_a: np.ndarray, img_b: np.ndarray, model: str, api_key: str | None = None,
            timeout_s: float = 60.0) -> str:
    """POST one image pair to ``url`` (OpenAI-compatible /chat/completions) -> the answer text."""
    if not url.startswith(("http://", "https://")):
        raise CountError(f"VLM url {url!r} must start with http:// or https://")
    body = json.dumps(vlm_request(img_a, img_b, model)).encode("utf-8")
    headers = {"Content-Type": "application/json"}
    if api_key:
        headers["Authorization"] = f"Bearer {api_key}"
    req = urllib.request.Request(url, data=body, headers=headers, method="POST")
    try:
        with urllib.request.urlopen(req, timeout=timeout_s) as resp:
            data = json.loads(resp.read().decode("utf-8"))
    except (urllib.error.URLError, TimeoutError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CountError(f"VLM request to {url} failed: {e}") from None
    try:
        return str(data["choices"][0]["message"]["content"])
    except (KeyError, IndexError, TypeError):
        raise CountError(f"VLM at {url} returned no choices[0].message.content") from None


def vlm_count(pairs: list[tuple[np.ndarray, np.ndarray]], url: str, model: str, api_key_env: str = "",
              timeout_s: float = 60.0) -> tuple[int, list[str]]:
    """Ask about every image pair; -> (mode of the parsed counts, raw answers). Failed requests count as
    unparsable answers; CountError when none parses."""
    key = os.environ.get(api_key_env) if api_key_env else None
    answers: list[str] = []
    for a, b in pairs:
        try:
            answers.append(ask_vlm(url, a, b, model, key, timeout_s))
        except CountError as e:
            answers.append(f"<error: {e}>")
    return mode_count([parse_count(t) for t in answers]), answers


def sample_image_pairs(obj, state_ids: list[str], m: int, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """M RGB pairs (same view id where possible) from two different states of an RSArtObject."""
    rng = np.random.default_rng(seed)
    pairs = []
    for _ in range(m):
        a, b = rng.choice(len(state_ids), 2, replace=False)
        va = obj.states[state_ids[a]].split("train") or obj.states[state_ids[a]].views
        vb = {v.id: v for v in (obj.states[state_ids[b]].split("train") or obj.states[state_ids[b]].views)}
        v1 = va[int(rng.integers(len(va)))]
        v2 = vb.get(v1.id) or list(vb.values())[int(rng.integers(len(vb)))]
        pairs.append((v1.rgb, v2.rgb))
    return pairs
