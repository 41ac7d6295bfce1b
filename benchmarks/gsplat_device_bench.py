"""GPU check of the gsplat backend: build time, differences from `reference`, and speed.

Run by ``benchmarks/gsplat_device_check.sh`` on a CUDA machine; each stage adds its keys to one
JSON file (``--out``), so a run cut short keeps what finished.

    python benchmarks/gsplat_device_bench.py build|diff|bench [--out FILE]

* build: imports gsplat's CUDA extension (JIT-compiled the first time) and times it.
* diff: the test scenes of tests/pd2gs/test_render_gsplat.py, gsplat vs reference: max and mean
  absolute differences of rgb/alpha/depth/label weights/means2d, gradient cosines and norm ratios.
  With ``--old FILE`` (a previous gsplat_backend.py) it also records how that version behaves.
* bench: one forward+backward (rasterize + L1 to a random image + backward) of N Gaussians in a
  W x H image, float32: gsplat with parameters on the GPU, gsplat with parameters on the CPU (as
  the trainer keeps them; includes the transfers), and the `cpu` backend on all CPU cores.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import pd2gs  # noqa: E402,F401  (sets OMP/numba threading defaults before torch loads)
import torch  # noqa: E402


def load(path: Path) -> dict:
    return json.loads(path.read_text()) if path.exists() else {}


def save(path: Path, key: str, value) -> None:
    data = load(path)
    data[key] = value
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, default=str) + "\n")
    print(f"[{key}] " + json.dumps(value, default=str)[:3000], flush=True)


def stage_build(out: Path) -> None:
    info = {"python": platform.python_version(), "torch": torch.__version__,
            "torch_cuda": torch.version.cuda, "cpus": os.cpu_count(),
            "TORCH_CUDA_ARCH_LIST": os.environ.get("TORCH_CUDA_ARCH_LIST"),
            "MAX_JOBS": os.environ.get("MAX_JOBS")}
    if torch.cuda.is_available():
        info["gpu"] = torch.cuda.get_device_name(0)
        info["capability"] = ".".join(map(str, torch.cuda.get_device_capability(0)))
    try:
        import gsplat
        info["gsplat"] = gsplat.__version__
    except ImportError as e:
        info["error"] = f"import gsplat: {e}"
        save(out, "build", info)
        return
    t0 = time.perf_counter()
    try:
        from gsplat.cuda._backend import _C
        info["extension_loaded"] = _C is not None
    except Exception as e:  # keep the compiler's message
        info["extension_loaded"] = False
        info["error"] = f"{type(e).__name__}: {str(e)[-4000:]}"
    info["build_s"] = round(time.perf_counter() - t0, 1)
    from pd2gs.render.gsplat_backend import gsplat_status
    info["gsplat_status"] = gsplat_status()
    save(out, "build", info)


def _cos(a, b) -> float:
    return float(torch.nn.functional.cosine_similarity(a.flatten().double(), b.flatten().double(),
                                                       dim=0))


def stage_diff(out: Path, old: str | None) -> None:
    from pd2gs.render import rasterize
    from tests.pd2gs.test_render import camera, random_scene
    from tests.pd2gs.test_render_gsplat import BG, render_loss

    rows = []
    for seed, n, opacity in [(0, 600, (0.05, 0.95)), (1, 400, (0.1, 0.1)), (2, 800, (0.5, 0.95)),
                             (3, 5000, (0.05, 0.95))]:
        width, height = 72, 50
        params = random_scene(n, torch.float32, seed, opacity)
        K, w2c = camera(width, height, torch.float32)
        labels = torch.randint(0, 3, (n,), generator=torch.Generator().manual_seed(seed))
        ref, gref = render_loss(params, K, w2c, width, height, "reference", labels)
        gs, ggs = render_loss(params, K, w2c, width, height, "gsplat", labels)
        row = {"seed": seed, "n": n, "opacity": opacity, "size": [width, height]}
        for name in ("rgb", "alpha", "label_weights"):
            d = (getattr(gs, name) - getattr(ref, name)).detach().abs()
            row[name] = {"max": float(d.max()), "mean": float(d.mean()),
                         "frac_gt_1e-3": float((d > 1e-3).float().mean())}
        solid = (ref.alpha > 0.2) & (gs.alpha > 0.2)
        dd = (gs.depth - ref.depth).detach().abs()[solid]
        row["depth_where_alpha_gt_0.2"] = {"max": float(dd.max()), "mean": float(dd.mean())}
        row["means2d_max"] = float((gs.means2d - ref.means2d).detach().abs()[ref.radii > 0].max())
        row["culled_agree"] = float(((gs.radii > 0) == (ref.radii > 0)).float().mean())
        grads = {}
        for name, a, b in zip(["means", "quats", "scales", "colors", "opacities"], ggs, gref):
            grads[name] = {"cos": _cos(a, b), "norm_ratio": float(a.norm() / b.norm())}
        g = gs.means2d.grad
        grads["means2d"] = (None if g is None else
                            {"cos": _cos(g, ref.means2d.grad),
                             "norm_ratio": float(g.norm() / ref.means2d.grad.norm())})
        row["grads"] = grads
        rows.append(row)
    result = {"rows": rows}

    if old and Path(old).exists():  # the version before this check, for the record
        spec = importlib.util.spec_from_file_location("old_gsplat_backend", old)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        params = random_scene(600, torch.float32, 0)
        K, w2c = camera(72, 50, torch.float32)
        rec = {}
        for tag, bg in (("with_background", torch.tensor(BG)), ("no_background", None)):
            try:
                o = mod.rasterize_gsplat(*params, K, w2c, 72, 50, bg, None, 0, False)
                o.means2d.retain_grad()
                o.rgb.sum().backward()
                with torch.no_grad():
                    ref = rasterize(*params, K, w2c, 72, 50, background=bg, backend="reference")
                vis = ref.radii > 0
                rec[tag] = {"ok": True, "rgb_device": str(o.rgb.device),
                            "rgb_max_diff": float((o.rgb.detach().cpu() - ref.rgb).abs().max()),
                            "means2d_max_diff": float((o.means2d.detach().cpu()
                                                       - ref.means2d).abs()[vis].max()),
                            "means2d_grad_is_none": o.means2d.grad is None}
            except Exception as e:
                rec[tag] = {"ok": False, "error": f"{type(e).__name__}: {str(e)[:500]}"}
        result["old_backend"] = rec
    save(out, "diff", result)


def bench_scene(n: int, seed: int = 0):
    """The sizing study's "mixed" scene (benchmarks/pd2gs_raster.py), leaf float32 tensors."""
    g = torch.Generator().manual_seed(seed)
    means = torch.rand(n, 3, generator=g) - 0.5
    quats = torch.randn(n, 4, generator=g)
    scales = 0.7 * n ** (-1 / 3) * torch.exp(0.3 * torch.randn(n, 3, generator=g))
    colors = torch.rand(n, 3, generator=g)
    opac = 0.05 + 0.9 * torch.rand(n, generator=g)
    return [means, quats, scales, colors, opac]


def time_steps(backend, params, K, w2c, width, height, target, warmup, reps, cuda) -> dict:
    times = []
    for i in range(warmup + reps):
        if cuda:
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        out = rasterize_fn()(*params, K, w2c, width, height, backend=backend)
        (out.rgb - target).abs().mean().backward()
        if cuda:
            torch.cuda.synchronize()
        t = time.perf_counter() - t0
        for p in params:
            p.grad = None
        if i >= warmup:
            times.append(t)
        else:
            print(f"  {backend} warm-up {i}: {t * 1e3:.1f} ms", flush=True)
    return {"median_ms": 1e3 * statistics.median(times), "min_ms": 1e3 * min(times),
            "reps": reps, "warmup": warmup}


def rasterize_fn():
    from pd2gs.render import rasterize
    return rasterize


def stage_bench(out: Path, n: int, width: int, height: int, reps: int, cpu_reps: int) -> None:
    base = bench_scene(n)
    f = 0.5 * width / math.tan(math.radians(20))
    K = torch.tensor([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]])
    w2c = torch.eye(4)
    w2c[2, 3] = 2.5
    target = torch.rand(height, width, 3, generator=torch.Generator().manual_seed(1))
    res = {"n": n, "width": width, "height": height, "scene": "mixed opacities U(0.05,0.95)",
           "step": "rasterize + L1 to a random image + backward, float32",
           "cpu_threads": torch.get_num_threads()}
    if torch.cuda.is_available():
        res["gpu"] = torch.cuda.get_device_name(0)
        dev = [p.cuda().requires_grad_() for p in base]
        res["gsplat_cuda_params"] = time_steps("gsplat", dev, K.cuda(), w2c.cuda(), width, height,
                                               target.cuda(), 3, reps, True)
        save(out, "bench", res)
        host = [p.clone().requires_grad_() for p in base]
        res["gsplat_cpu_params"] = time_steps("gsplat", host, K, w2c, width, height, target, 2,
                                              reps, True)
        save(out, "bench", res)
    host = [p.clone().requires_grad_() for p in base]
    res["cpu_backend"] = time_steps("cpu", host, K, w2c, width, height, target, 1, cpu_reps, False)
    if "gsplat_cuda_params" in res:
        res["speedup_gsplat_cuda_vs_cpu"] = (res["cpu_backend"]["median_ms"]
                                             / res["gsplat_cuda_params"]["median_ms"])
        res["speedup_gsplat_cpu_params_vs_cpu"] = (res["cpu_backend"]["median_ms"]
                                                   / res["gsplat_cpu_params"]["median_ms"])
    save(out, "bench", res)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("stage", choices=["build", "diff", "bench"])
    ap.add_argument("--out", default=os.path.join(os.environ.get("OUT", "."), "gsplat-device.json"))
    ap.add_argument("--old", default=None, help="a previous gsplat_backend.py to record (diff)")
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--cpu-reps", type=int, default=3)
    args = ap.parse_args()
    out = Path(args.out)
    if args.stage == "build":
        stage_build(out)
    elif args.stage == "diff":
        stage_diff(out, args.old)
    else:
        w, h = map(int, args.size.split("x"))
        stage_bench(out, args.n, w, h, args.reps, args.cpu_reps)


if __name__ == "__main__":
    main()
