"""The fuzz campaign of docs/reliability.md: many random calls of facetlift.integrate per method,
counted by outcome, without stopping at the first failure.

The draws are those of tests/test_properties.py (shapes 1-40, masks, bad normals, dtypes, K,
`known`, valid and invalid option values from each method's declarations). Every call must
return finite depth on the mask or raise a documented error (ValueError, SolverError,
MemoryLimitError) within the time bound; anything else is listed.

    .venv/bin/python benchmarks/fuzz.py --examples 1500 --json fuzz.json
"""

from __future__ import annotations

import argparse
import collections
import json
import re
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import test_properties as tp  # noqa: E402
from hypothesis import HealthCheck, given, seed, settings  # noqa: E402

from facetlift.methods import REGISTRY  # noqa: E402


def campaign(method: str, examples: int, base_seed: int) -> collections.Counter:
    counts: collections.Counter = collections.Counter()

    @settings(max_examples=examples, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(data=tp.normal_maps(), opts=tp.method_options(method))
    def prop(data, opts):
        t0 = time.perf_counter()
        try:
            outcome = tp.check_call(method, data, opts)
        except AssertionError as e:
            outcome = f"BROKEN PROPERTY: {str(e)[:80]}"
        except Exception as e:
            outcome = f"UNDOCUMENTED {type(e).__name__}: {str(e)[:80]}"
        counts[re.sub(r"\d+(\.\d+)?(e-?\d+)?", "N", outcome)] += 1
        counts["_seconds"] += time.perf_counter() - t0

    seed(base_seed)(prop)()
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=1500, help="calls per method")
    ap.add_argument("--methods", default=",".join(REGISTRY))
    ap.add_argument("--seed", type=int, default=12)
    ap.add_argument("--json", help="write the counts here")
    args = ap.parse_args()
    report = {}
    for m in args.methods.split(","):
        c = campaign(m, args.examples, args.seed)
        seconds = c.pop("_seconds")
        total = sum(c.values())
        bad = {k: v for k, v in c.items() if k.startswith(("UNDOCUMENTED", "BROKEN"))}
        report[m] = {"calls": total, "ok": c.get("ok", 0), "refused": c.get("refused", 0),
                     "undocumented": bad, "seconds": seconds}
        print(f"{m:18s} {total:6d} calls: {c.get('ok', 0):5d} ok, {c.get('refused', 0):5d} "
              f"refused, {sum(bad.values())} undocumented, {seconds:.1f} s", flush=True)
        for k, v in sorted(bad.items(), key=lambda kv: -kv[1]):
            print(f"    {v:5d}  {k}")
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
