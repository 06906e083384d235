"""The system around the kernel, measured as a user meets it: command latency with and without the
compilation cache, and a large Monte Carlo search's memory and rate against the raw solve rate,
all in one run.

1. **Latency.** `jaxlink kinematics sewing-feed --rpm 2500 --csv f.csv` twice with
   `JAXLINK_CACHE_DIR` set to a fresh directory (cold: compiles and fills the cache; warm: loads
   the compiled code), and once with the cache off (`JAXLINK_CACHE_DIR=""`).
   **`check` latency** (issue 24: ≤ 2 s cold, ≤ 1 s warm on 2 cores): `jaxlink check four-bar`,
   `jaxlink check whitworth` and a triple-rocker (`check four-bar --set b=40 --set c=30`: limit
   positions), each `--runs` times (default 5) with a fresh cache directory
   (cold) and again with it filled (warm); the median and the range of each, with the load
   average (1 min) before and after, since the machine may be shared.
2. **Search rate.** `jaxlink optimize sewing-feed-opt --method montecarlo --budget B --progress off
   --out R.json` (B = 3e6; `--quick` 3e5): peak resident memory of the process, and the search's
   positions/s (evaluations × samples / `search_wall_s`, or `wall_s` where the JSON has no
   `search_wall_s`) against `throughput.py --quick --jaxlink-only` positions/s in the same run.

    python benchmarks/system.py [--quick] [--latency-only] [--runs N] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from _cores import default_output

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


# the command line, reporting its own peak resident memory on exit
CLI = ("import atexit, resource, runpy, sys; "
       "atexit.register(lambda: print('PEAK_RSS_KB', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, "
       "file=sys.stderr)); sys.argv = ['jaxlink'] + sys.argv[1:]; runpy.run_module('jaxlink.cli', run_name='__main__')")


def timed(args, env, cwd):
    """(wall seconds, peak RSS of the command in MB, completed process)."""
    t = time.perf_counter()
    r = subprocess.run(args, env=env, cwd=cwd, capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - t
    peak = [int(x.split()[1]) for x in r.stderr.splitlines() if x.startswith("PEAK_RSS_KB")]
    return wall, (peak[-1] / 1024 if peak else float("nan")), r


#: the linkages of the `check` latency: a crank-rocker, the Whitworth quick return (RPR and RRP dyads,
#: a slider's stroke) and a triple-rocker of the four-bar's structure (its input's limit positions:
#: a = 20, b = 40, c = 30, d = 55 mm, s + l > p + q)
CHECK_CASES = {"four-bar": ["four-bar"], "whitworth": ["whitworth"],
               "triple-rocker": ["four-bar", "--set", "b=40", "--set", "c=30"]}


def check_latency(cli, tmp, runs: int, scenes=tuple(CHECK_CASES)) -> dict:
    """`jaxlink check SCENE` (`CHECK_CASES`) cold (a fresh cache directory) then warm (the same
    again), `runs` times per scene, alternating the scenes: the median and range of each, the load average, and
    the CPU time (user + system) of each run: on a shared machine the wall time is that CPU time
    spread over the cores it got (a cold `check` compiles on two threads)."""
    times: dict = {s: {"cold": [], "warm": []} for s in scenes}
    cpu: dict = {s: {"cold": [], "warm": []} for s in scenes}
    ok = True
    load_before = os.getloadavg()[0]
    for i in range(runs):
        for scene in scenes:
            env = dict(os.environ, JAXLINK_CACHE_DIR=os.path.join(tmp, f"check-{scene}-{i}"))
            for kind in ("cold", "warm"):
                before = os.times()
                wall, _, r = timed(cli + ["check", *CHECK_CASES[scene]], env, tmp)
                after = os.times()
                times[scene][kind].append(wall)
                cpu[scene][kind].append(after.children_user + after.children_system
                                        - before.children_user - before.children_system)
                ok = ok and r.returncode == 0
    load_after = os.getloadavg()[0]
    out: dict = {"runs": runs, "load_1min_before": load_before, "load_1min_after": load_after,
                 "cpus": len(os.sched_getaffinity(0)), "ok": ok}
    for scene in scenes:
        out[scene] = {f"{k}_{stat}": f(v) for k, v in times[scene].items()
                      for stat, f in (("median_s", statistics.median), ("min_s", min), ("max_s", max))}
        out[scene].update({f"{k}_s": v for k, v in times[scene].items()})
        out[scene].update({f"{k}_cpu_median_s": statistics.median(v) for k, v in cpu[scene].items()})
        out[scene].update({f"{k}_cpu_s": v for k, v in cpu[scene].items()})
        c, w = out[scene]["cold_median_s"], out[scene]["warm_median_s"]
        print(f"check {scene}: cold {c:.2f} s ({min(times[scene]['cold']):.2f}–{max(times[scene]['cold']):.2f}), "
              f"warm {w:.2f} s ({min(times[scene]['warm']):.2f}–{max(times[scene]['warm']):.2f}), median of {runs}; "
              f"CPU cold {out[scene]['cold_cpu_median_s']:.2f} s, warm {out[scene]['warm_cpu_median_s']:.2f} s; "
              f"goal ≤ 2 s cold, ≤ 1 s warm", flush=True)
    print(f"check latency: load average (1 min) {load_before:.2f} before, {load_after:.2f} after, "
          f"{out['cpus']} cores{'' if ok else '  (a run failed)'}", flush=True)
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a 3e5-design search instead of 3e6")
    ap.add_argument("--latency-only", action="store_true", help="the latency figures only (no search)")
    ap.add_argument("--runs", type=int, default=5, help="runs of each `check` latency (default 5; the median)")
    ap.add_argument("--json", metavar="OUT", help="write the results as JSON (default: benchmarks/results/latest/)")
    args = ap.parse_args(argv)
    out: dict = {}
    cli = [sys.executable, "-c", CLI]
    with tempfile.TemporaryDirectory(prefix="jaxlink_system_") as tmp:
        # 1. latency
        kin = cli + ["kinematics", "sewing-feed", "--rpm", "2500", "--csv", os.path.join(tmp, "f.csv")]
        cache = os.path.join(tmp, "xla")
        env = dict(os.environ, JAXLINK_CACHE_DIR=cache)
        cold, _, r1 = timed(kin, env, tmp)
        warm, _, r2 = timed(kin, env, tmp)
        off, _, r3 = timed(kin, dict(os.environ, JAXLINK_CACHE_DIR=""), tmp)
        ok = all(r.returncode == 0 for r in (r1, r2, r3))
        out["latency"] = {"command": "jaxlink kinematics sewing-feed --rpm 2500 --csv f.csv", "cold_s": cold,
                          "warm_s": warm, "uncached_s": off, "warm_over_cold": warm / cold, "ok": ok}
        print(f"latency: cold {cold:.2f} s, warm {warm:.2f} s ({100 * warm / cold:.0f} % of cold), "
              f"cache off {off:.2f} s{'' if ok else '  (a run failed)'}", flush=True)
        out["check_latency"] = check_latency(cli, tmp, args.runs)
        if args.latency_only:
            path = args.json or default_output("system-latency.json")
            with open(path, "w") as f:
                json.dump(out, f, indent=1)
            print(f"wrote {path}")
            return out

        # 2. the raw rate, then the search
        tp_json = os.path.join(tmp, "tp.json")
        subprocess.run([sys.executable, os.path.join(HERE, "throughput.py"), "--quick", "--jaxlink-only",
                        "--cores", str(len(os.sched_getaffinity(0))), "--json", tp_json],
                       cwd=ROOT, capture_output=True, text=True, timeout=1800)
        raw = json.load(open(tp_json))["positions_per_s"] if os.path.exists(tp_json) else None
        budget = 300_000 if args.quick else 3_000_000
        res = os.path.join(tmp, "R.json")
        wall, rss, r = timed(cli + ["optimize", "sewing-feed-opt", "--method", "montecarlo", "--budget", str(budget),
                                    "--progress", "off", "--out", res], dict(os.environ, JAXLINK_CACHE_DIR=""), tmp)
        doc = json.load(open(res)) if r.returncode == 0 else {}
        search_s = doc.get("search_wall_s", doc.get("wall_s"))
        rate = doc["evaluations"] * doc["samples"] / search_s if doc else None
        out["search"] = {"budget": budget, "process_wall_s": wall, "peak_rss_mb": rss, "search_wall_s": search_s,
                         "evaluations": doc.get("evaluations"), "samples": doc.get("samples"),
                         "positions_per_s": rate, "raw_positions_per_s": raw,
                         "ratio_vs_raw": (rate / raw) if rate and raw else None,
                         "best_objective": (doc.get("best") or {}).get("objective"),
                         "error": None if r.returncode == 0 else r.stderr.strip().splitlines()[-3:]}
        s = out["search"]
        print(f"Monte Carlo {budget} designs: process {wall:.1f} s, search {search_s} s, peak RSS {rss:.0f} MB, "
              f"{rate or 0:.3g} positions/s = {100 * (s['ratio_vs_raw'] or 0):.0f} % of the raw solve rate "
              f"({raw or 0:.3g} positions/s, throughput.py --quick --jaxlink-only, same run)", flush=True)
    path = args.json or default_output("system.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=1)
    print(f"wrote {path}")
    return out


if __name__ == "__main__":
    main()
