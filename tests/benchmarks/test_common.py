"""benchmarks/common.py. cpu_description: timed results name the processor well enough to tell two
"AMD EPYC" machines apart (one with AVX-512 ran the CPU rasterizer 3.5x faster than one without).
write_report: a report's table and record never go to one file."""
from __future__ import annotations

import json
import platform

from tests.benchmarks.bench_helpers import load

CPUINFO = """processor\t: 0
vendor_id\t: AuthenticAMD
cpu family\t: 25
model\t\t: 17
model name\t: AMD EPYC 9R14 96-Core Processor
cpu MHz\t\t: 3699.998
flags\t\t: fpu vme sse sse2 avx avx2 fma avx512f avx512dq

processor\t: 1
vendor_id\t: GenuineIntel
model name\t: something else
cpu MHz\t\t: 1.0
flags\t\t: fpu
"""


def _common():
    return load("common.py")


def test_first_cpu_model_clock_and_widest_avx(tmp_path):
    f = tmp_path / "cpuinfo"
    f.write_text(CPUINFO)
    assert _common().cpu_description(f) == "AMD EPYC 9R14 96-Core Processor (family 25 model 17), 3700 MHz, AVX-512"


def test_avx2_only_and_no_clock(tmp_path):
    f = tmp_path / "cpuinfo"
    f.write_text("model name\t: AMD EPYC\ncpu family\t: 25\nmodel\t\t: 1\nflags\t\t: sse avx avx2 fma\n")
    assert _common().cpu_description(f) == "AMD EPYC (family 25 model 1), AVX2"


def test_no_cpuinfo_falls_back_to_platform(tmp_path):
    assert _common().cpu_description(tmp_path / "missing") == (platform.processor() or platform.machine())


def test_machine_record_uses_it():
    assert _common().machine(load=[1.0])["processor"] == _common().cpu_description()


def test_write_report_never_writes_table_and_record_to_one_file(tmp_path):
    """`--out x.json` used to write the markdown table to x.json and then replace it with the record."""
    for name in ("r.md", "r.json", "r"):
        md, js = _common().write_report(tmp_path / "out" / name, "| a |\n", {"k": 1})
        assert (md, js) == (tmp_path / "out" / "r.md", tmp_path / "out" / "r.json")
        assert md.read_text() == "| a |\n"
        assert json.loads(js.read_text()) == {"k": 1}
