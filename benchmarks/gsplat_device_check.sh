#!/usr/bin/env bash
# GPU check of pd2gs's gsplat backend: install gsplat from carried wheels, JIT-build its CUDA
# extension, run tests/pd2gs/test_render_gsplat.py, record differences and timings.
#
# Needs a CUDA machine with python3 + torch (CUDA build), nvcc and ninja. gsplat (a pure-Python
# wheel that compiles its CUDA code at first use) and any other missing wheels go in .whl/
# (ignored via .git/info/exclude), fetched on a machine with internet:
#   echo /.whl/ >> .git/info/exclude
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \
#       --implementation cp --platform manylinux_2_28_x86_64 -d .whl gsplat==1.5.3
# Optionally put the previous backend at .whl/old_gsplat_backend.py to record how it behaved.
# In this workplace: run tool, carry [".whl"], command "bash benchmarks/gsplat_device_check.sh",
# timeout_s 540. Results land in $OUT (default /tmp/gsplat_check): gsplat-device.json, *.log.
#
# DISCOVERY_DATA=<rendered object folder> adds an end-to-end run (benchmarks/gsplat_device_discovery.py:
# training and articulated discovery on gsplat; DISCOVERY_CPU=1 also discovery on cpu); SKIP_BENCH=1 skips
# the rasterizer timing.
# Env: TORCH_CUDA_ARCH_LIST (default: the GPU's own capability), MAX_JOBS (default: cores),
# N / SIZE / REPS / CPU_REPS for the benchmark (default 100000 / 640x480 / 20 / 3).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/gsplat_check}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
T0=$(date +%s)
stamp() { echo "=== $1 at +$(( $(date +%s) - T0 )) s" | tee -a "$OUT/steps.log"; }

stamp "install wheels"
if ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH}
fi
export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
if [ -z "${TORCH_CUDA_ARCH_LIST:-}" ]; then
  TORCH_CUDA_ARCH_LIST=$(python3 -c "import torch; print('%d.%d' % torch.cuda.get_device_capability(0))" 2>/dev/null || echo "")
  [ -n "$TORCH_CUDA_ARCH_LIST" ] && export TORCH_CUDA_ARCH_LIST
fi
export MAX_JOBS=${MAX_JOBS:-$(nproc)}
{
  date -u +%Y-%m-%dT%H:%M:%SZ
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
  nvcc --version | tail -2
  python3 -c "import torch, numba; print('torch', torch.__version__, 'cuda', torch.version.cuda, 'numba', numba.__version__)"
  echo "TORCH_CUDA_ARCH_LIST=${TORCH_CUDA_ARCH_LIST:-} MAX_JOBS=$MAX_JOBS nproc=$(nproc)"
} 2>&1 | tee "$OUT/env.txt"

stamp "build gsplat CUDA extension"
python3 benchmarks/gsplat_device_bench.py build --out "$OUT/gsplat-device.json" 2>&1 | tee "$OUT/build.log"

stamp "pytest"
# --noconftest: tests/conftest.py needs trimesh (not needed here); the tests use no fixtures of it
python3 -m pytest -v -rA --noconftest -p no:cacheprovider --durations=10 \
  tests/pd2gs/test_render_gsplat.py 2>&1 | tee "$OUT/pytest.log"
echo "pytest exit ${PIPESTATUS[0]}" | tee -a "$OUT/steps.log"

stamp "diff vs reference"
OLD=""
[ -f .whl/old_gsplat_backend.py ] && OLD="--old .whl/old_gsplat_backend.py"
python3 benchmarks/gsplat_device_bench.py diff $OLD --out "$OUT/gsplat-device.json" 2>&1 | tee "$OUT/diff.log"

if [ -n "${SKIP_BENCH:-}" ]; then stamp "bench skipped (SKIP_BENCH)"; else
stamp "bench"
python3 benchmarks/gsplat_device_bench.py bench --n "${N:-100000}" --size "${SIZE:-640x480}" \
  --reps "${REPS:-20}" --cpu-reps "${CPU_REPS:-3}" --out "$OUT/gsplat-device.json" 2>&1 | tee "$OUT/bench.log"
fi

if [ -n "${DISCOVERY_DATA:-}" ]; then
  # end to end: train one object's field and run the articulated discovery on gsplat (joints only: meshing
  # needs open3d, which cannot travel); DISCOVERY_CPU=1 adds the same discovery on the cpu backend
  stamp "discovery on gsplat ($DISCOVERY_DATA)"
  python3 benchmarks/gsplat_device_discovery.py --data "$DISCOVERY_DATA" --work /tmp/gsplat_discovery \
    --out "$OUT" ${DISCOVERY_CPU:+--cpu-discovery} 2>&1 | tee "$OUT/discovery.log"
fi
stamp "done"
