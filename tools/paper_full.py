#!/usr/bin/env python3
"""The full ``vdps paper`` run: >= 20 seeds per profile (table1-susp1k and table1), every
experiment at full length (the whole test-track scenarios, Table 3 over 40 s, 3 seeds per SNR
row), in parallel over ``--workers`` processes; prints the side-by-side table (paper vs ours)
and writes the JSON document (``vdps_hil.experiments.paper_run.run_paper``; keys as ``vdps paper --json``).

Usage::

    .venv/bin/python tools/paper_full.py [--seeds 20] [--workers 2] [--profile NAME ...]
                                         [--json paper_full.json]

Takes about 20-30 minutes on 2 cores (one paper-left-turn drive through the whole chain with the
10 Hz predictor is ~15 s of CPU).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vdps_hil.cli.common import _clean  # noqa: E402
from vdps_hil.experiments.paper_report import format_report  # noqa: E402
from vdps_hil.experiments.paper_run import PROFILES, PaperOptions, run_paper  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--snr-seeds", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--profile", action="append", default=None)
    ap.add_argument("--json", default="paper_full.json")
    a = ap.parse_args(argv)
    if a.seeds < 20:
        print(f"note: {a.seeds} seeds (the acceptance figures are over >= 20)", file=sys.stderr)
    opt = PaperOptions(profiles=tuple(a.profile or PROFILES), seeds=a.seeds, snr_seeds=a.snr_seeds,
                       workers=a.workers)
    t0 = time.perf_counter()

    def progress(done, total):
        print(f"  {done}/{total} runs, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    doc = run_paper(opt, progress=progress)
    print(format_report(doc))
    if a.json:
        Path(a.json).write_text(json.dumps(_clean(doc), indent=2, sort_keys=True) + "\n", encoding="utf-8")
        print(f"JSON: {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
