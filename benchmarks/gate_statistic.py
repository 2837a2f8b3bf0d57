"""The gate-statistic study of issue 31 (``oapo_lite/study/gate_study.py`` says what it measures and
the rule that chooses): trains what is missing, then prints the table and the choice.

    .venv/bin/python benchmarks/gate_statistic.py --seeds 0 1 2            # every env
    .venv/bin/python benchmarks/gate_statistic.py --envs smax:3m --seeds 0  # a part of it
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from oapo_lite.study import gate_study  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--envs", nargs="+", default=list(gate_study.ENVS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    args = parser.parse_args(argv)
    gate_study.run(args.envs, args.seeds)
    df = gate_study.load()
    table = gate_study.summary(df)
    pd.set_option("display.width", 160)
    print(f"seeds on disk per env: {df.groupby('env')['seed'].nunique().to_dict()}")
    print(table.round(3).to_string())
    stat, why = gate_study.choose(table)
    print(f"chosen at sigma = {gate_study.SIGMA:g}: {stat!r}: {why}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
