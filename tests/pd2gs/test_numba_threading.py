"""numba's threading layer: OpenMP first, so an old TBB never gets a chance to print its NumbaWarning."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
KERNEL = """
import warnings
from numba.core.errors import NumbaWarning
warnings.simplefilter("error", NumbaWarning)
import numpy as np
from numba import njit, prange

@njit(parallel=True)
def total(x):
    s = 0.0
    for i in prange(x.shape[0]):
        s += x[i]
    return s

assert total(np.ones(64)) == 64.0
print(" ".join(numba.config.THREADING_LAYER_PRIORITY), numba.threading_layer())
"""


@pytest.mark.parametrize("first", ["import pd2gs, numba", "import numba, pd2gs"])
def test_openmp_layer_first_without_warnings(first):
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env["OMP_NUM_THREADS"] = "1"
    r = subprocess.run([sys.executable, "-c", first + "\n" + KERNEL], capture_output=True, text=True, env=env,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    prio, layer = r.stdout.split()[:3], r.stdout.split()[3]
    assert prio == ["omp", "workqueue", "tbb"] and layer in ("omp", "workqueue")
    assert "Warning" not in r.stderr


def test_a_users_choice_is_kept():
    env = dict(os.environ, NUMBA_THREADING_LAYER_PRIORITY="workqueue omp tbb",
               PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-c", "import pd2gs, numba\n" + KERNEL], capture_output=True, text=True,
                       env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["workqueue", "omp", "tbb", "workqueue"]


OLD_TBB = os.environ.get("RSART_OLD_TBB_LIB")  # a folder with libtbb.so.12 older than 2021.6 (e.g. the tbb 2021.5.1 wheel's lib/)


@pytest.mark.skipif(not OLD_TBB, reason="set RSART_OLD_TBB_LIB to a folder holding an old libtbb.so.12 "
                                        "(pip download tbb==2021.5.1 --no-deps; unzip; its .data/data/lib)")
def test_an_old_tbb_warns_without_pd2gs_and_not_with_it():
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(PYTHONPATH=str(REPO) + os.pathsep + env.get("PYTHONPATH", ""), OMP_NUM_THREADS="1",
               LD_LIBRARY_PATH=OLD_TBB + os.pathsep + env.get("LD_LIBRARY_PATH", ""))
    plain = KERNEL.replace('warnings.simplefilter("error", NumbaWarning)', "").replace(
        'print(" ".join(numba.config.THREADING_LAYER_PRIORITY), numba.threading_layer())', "")
    r = subprocess.run([sys.executable, "-c", "import numba\n" + plain], capture_output=True, text=True, env=env,
                       timeout=300)
    assert "TBB threading layer requires TBB version" in r.stderr  # the environment reproduces the problem
    r = subprocess.run([sys.executable, "-c", "import pd2gs, numba\n" + KERNEL], capture_output=True, text=True,
                       env=env, timeout=300)
    assert r.returncode == 0 and "NumbaWarning" not in r.stderr, r.stderr
