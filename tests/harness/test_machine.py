"""``bench.machine``: the CPU a result was measured on, in every job row and in the tables' timing section."""

from __future__ import annotations

import pandas as pd

from bench.machine import cpu_description, describe_cpu
from bench.table_markdown import _cpu_line

CPUINFO = """processor\t: 0
vendor_id\t: AuthenticAMD
cpu family\t: 25
model\t\t: 17
model name\t: AMD EPYC

processor\t: 1
vendor_id\t: AuthenticAMD
cpu family\t: 25
model\t\t: 17
model name\t: AMD EPYC
"""


def test_describe_cpu_names_model_family_and_count():
    assert describe_cpu(CPUINFO, 2) == "AMD EPYC (family 25, model 17), 2 logical CPUs"
    assert describe_cpu(None, 4, fallback="x86_64") == "x86_64, 4 logical CPUs"  # no /proc/cpuinfo
    assert describe_cpu("", None) == "unknown CPU"


def test_this_machine_is_described():
    assert cpu_description().endswith("logical CPUs")  # os.cpu_count() is known on the machines CI runs on


def test_cpu_line_counts_jobs_per_cpu_and_the_unrecorded_ones():
    jobs = pd.DataFrame({"cpu": ["A (family 25, model 17), 2 logical CPUs"] * 2 + ["B, 2 logical CPUs", None]})
    line = _cpu_line(jobs)
    assert "A (family 25, model 17), 2 logical CPUs (2 jobs)" in line and "B, 2 logical CPUs (1 job)" in line
    assert "not recorded (1 job" in line
    assert _cpu_line(pd.DataFrame({"x": [1]})).startswith("Measured on: not recorded (1 job")
