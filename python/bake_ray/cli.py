"""`bake-ray run PIPELINE.ron [--address ADDR] [--json] [--bin-dir DIR]`."""

import argparse
import json
import os
import sys

from .executor import BLOCKED, FAILED, BakeRayError, run


def _table(report):
    rows = [("STAGE", "KIND", "STATUS", "TIME", "NODE")]
    for s in report["stages"]:
        t = "%.2f s" % s["seconds"] if s["node"] else "-"
        rows.append((s["id"], s["kind"], s["status"], t, (s["node"] or "-")[:12]))
    widths = [max(len(r[c]) for r in rows) for c in range(len(rows[0]))]
    for r in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(r, widths)).rstrip())
    count = lambda st: sum(1 for s in report["stages"] if s["status"] == st)
    print(
        "\n%d ran, %d restored, %d up to date, %d skipped, %d failed, %d blocked in %.2f s "
        "(%d tasks on %d nodes)"
        % (
            count("ran"), count("restored"), count("up-to-date"), count("skipped"),
            count(FAILED), count(BLOCKED), report["seconds"], report["tasks_submitted"],
            len({s["node"] for s in report["stages"] if s["node"]}),
        )
    )


def main(argv=None):
    ap = argparse.ArgumentParser(
        prog="bake-ray",
        description="Run an ibl-bake pipeline on a Ray cluster, with the same cache and "
        "byte-identical results as `bake run`.",
    )
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run a pipeline: one Ray task per stage that must run")
    r.add_argument("pipeline", help="the pipeline (.ron)")
    r.add_argument("--address", help="a Ray cluster (host:port); default: start a local one on 127.0.0.1")
    r.add_argument("--json", action="store_true", help="print the report as JSON on stdout")
    r.add_argument("--bin-dir", help="folder of the `bake` binary (default: $BAKE_RAY_BIN_DIR, then PATH)")
    r.add_argument("--max-retries", type=int, default=3, help="retries of a task whose worker died (default 3)")
    r.add_argument("--num-cpus", type=float, default=1, help="CPUs each stage task reserves (default 1)")
    r.add_argument("--no-spread", action="store_true", help="default Ray scheduling instead of SPREAD")
    r.add_argument("-q", "--quiet", action="store_true", help="no per-stage lines on stderr")
    a = ap.parse_args(argv)
    log = (lambda m: None) if a.quiet else (lambda m: print(m, file=sys.stderr, flush=True))
    # Ray prints (worker deaths, retries) on stdout; with --json only the report goes there.
    json_out = None
    if a.json:
        sys.stdout.flush()
        json_out = os.fdopen(os.dup(1), "w")
        os.dup2(2, 1)
    try:
        report = run(
            a.pipeline,
            address=a.address,
            bin_dir=a.bin_dir,
            max_retries=a.max_retries,
            num_cpus=a.num_cpus,
            spread=not a.no_spread,
            log=lambda m: print(m, file=sys.stderr, flush=True) if "error:" in m else log(m),
        )
    except BakeRayError as e:
        print("bake-ray: error: %s" % e, file=sys.stderr)
        return e.code
    except KeyboardInterrupt:
        print("bake-ray: interrupted; completed stages are kept, the next run resumes from them",
              file=sys.stderr)
        return 130
    if json_out is not None:
        sys.stdout.flush()
        json_out.write(json.dumps(report, indent=2) + "\n")
        json_out.flush()
    else:
        _table(report)
    if report["interrupted"]:
        print("bake-ray: interrupted; completed stages are kept, the next run resumes from them",
              file=sys.stderr)
        return 130
    bad = any(s["status"] in (FAILED, BLOCKED) for s in report["stages"])
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
