"""Where the default test suite's compilation time goes, from a log written by
``benchmarks/suite_compile/complog.py`` (one line per XLA compilation: test id, program name,
seconds; plain or gzipped): the total, and the programs and test modules that compiled longest.
The record of 2026-11-28 (the suite in place, 702 tests, before the least-squares padding):
``benchmarks/records/performance/suite_compile_20261128.tsv.gz``; docs/measurements.md quotes it.

    python benchmarks/suite_compile_summary.py benchmarks/records/performance/suite_compile_20261128.tsv.gz
"""
import sys

import pandas as pd

d = pd.read_csv(sys.argv[1], sep="\t", names=["test", "program", "s"])
d["module"] = d["test"].str.split("::").str[0]
print(f"{d['s'].sum():.1f} s of compilation in {len(d)} programs")
for key in ("program", "module"):
    top = d.groupby(key)["s"].agg(["size", "sum"]).sort_values("sum", ascending=False).head(10)
    print(f"\nby {key}:\n{top.round(1).to_string()}")
