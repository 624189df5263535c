#!/usr/bin/env python3
"""Writes BENCHMARKS.md from criterion's estimates and the CLI's output.

Runs every benchmark listed in benches/benchmarks.toml (each with its own
criterion folder, so that ids of different crates do not mix), then the
listed commands, and writes one table per benchmark target, with the
machine and the commit. BENCHMARKS.md is this script's output: edit the
TOML or the benches, never the file.

  python3 scripts/benchmarks.py                 # everything, criterion's defaults
  python3 scripts/benchmarks.py --quick         # criterion --quick (CI checks this runs)
  python3 scripts/benchmarks.py --only atmo-core --out /tmp/B.md
"""

import argparse
import datetime
import json
import os
import pathlib
import re
import subprocess
import sys
import tempfile
import time
import tomllib

ROOT = pathlib.Path(__file__).resolve().parent.parent


def sh(args, **kw):
    return subprocess.run(args, cwd=ROOT, text=True, capture_output=True, **kw)


def machine():
    """One line: CPU model, cores, memory, rustc, commit, date."""
    model = "unknown CPU"
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        kb = int(pathlib.Path("/proc/meminfo").read_text().split()[1])
        mem = f", {kb / 1024 / 1024:.0f} GiB"
    except (OSError, ValueError, IndexError):
        pass
    rustc = sh(["rustc", "-V"]).stdout.strip()
    commit = sh(["git", "rev-parse", "--short", "HEAD"]).stdout.strip() or "unknown"
    dirty = " (uncommitted changes)" if sh(["git", "status", "--porcelain", "--untracked-files=no"]).stdout.strip() else ""
    load = ""
    try:
        load = f"; load average {os.getloadavg()[0]:.1f} at the start"
    except OSError:
        pass
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return (f"{model}, {os.cpu_count()} cores{mem}; {rustc}; commit {commit}{dirty}; "
            f"{when}{load}")


def fmt_time(ns):
    for unit, scale in (("s", 1e9), ("ms", 1e6), ("us", 1e3)):
        if ns >= scale:
            return f"{ns / scale:.3g} {unit}"
    return f"{ns:.3g} ns"


def read_estimates(home):
    """(id, median ns, lower, upper) of every benchmark under a criterion home."""
    rows = []
    for est in sorted(pathlib.Path(home).glob("**/new/estimates.json")):
        bench = est.parent / "benchmark.json"
        if not bench.exists():
            continue
        full_id = json.loads(bench.read_text())["full_id"]
        median = json.loads(est.read_text())["median"]
        ci = median["confidence_interval"]
        rows.append((full_id, median["point_estimate"], ci["lower_bound"], ci["upper_bound"]))
    return rows


def run_bench(entry, home, quick):
    args = ["cargo", "bench", "-p", entry["package"], "--bench", entry["bench"], "--", "--noplot"]
    if quick:
        args.append("--quick")
    env = dict(os.environ, CRITERION_HOME=str(home))
    print("$ " + " ".join(args), file=sys.stderr, flush=True)
    done = subprocess.run(args, cwd=ROOT, env=env, text=True, capture_output=True)
    if done.returncode != 0:
        sys.exit(f"benchmarks.py: `{' '.join(args)}` failed:\n{done.stderr[-3000:]}")
    return " ".join(args[:6]) + (" -- --quick" if quick else "")


def run_command(entry, scratch):
    args = [a.replace("{out}", str(scratch)) for a in entry["run"]]
    print("$ " + " ".join(args), file=sys.stderr, flush=True)
    start = time.monotonic()
    done = sh(args)
    wall = time.monotonic() - start
    if done.returncode != 0:
        sys.exit(f"benchmarks.py: `{' '.join(args)}` failed:\n{done.stderr[-3000:]}")
    keep = re.compile(entry["keep"])
    lines = [l.rstrip() for l in done.stdout.splitlines() if keep.search(l)]
    shown = " ".join(a if not a.startswith(str(scratch)) else "OUT" for a in args)
    return shown, wall, lines


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="criterion's --quick (fewer samples)")
    ap.add_argument("--only", metavar="PACKAGE", help="only this package's benchmarks, no commands")
    ap.add_argument("--out", default=str(ROOT / "BENCHMARKS.md"), help="the file to write")
    a = ap.parse_args()

    spec = tomllib.loads((ROOT / "benches" / "benchmarks.toml").read_text())
    header = machine()
    out = [
        "# Benchmarks",
        "",
        "Written by `python3 scripts/benchmarks.py"
        + (" --quick" if a.quick else "") + "` (do not edit: change the benches or "
        "`benches/benchmarks.toml` and run it again). Criterion medians with their 95 % "
        "interval; release (bench) profile.",
        "",
        f"Machine: {header}.",
        "",
    ]
    with tempfile.TemporaryDirectory(prefix="atmo-benchmarks-") as tmp:
        tmp = pathlib.Path(tmp)
        for entry in spec["bench"]:
            if a.only and entry["package"] != a.only:
                continue
            home = tmp / f"{entry['package']}-{entry['bench']}"
            command = run_bench(entry, home, a.quick)
            rows = read_estimates(home)
            notes = entry.get("notes", {})
            out += [f"## {entry['title']}", "", entry["about"], "", f"`{command}`", "",
                    "| benchmark | median | 95 % interval | what it runs |", "| --- | --- | --- | --- |"]
            for full_id, med, lo, hi in rows:
                out.append(f"| `{full_id}` | {fmt_time(med)} | {fmt_time(lo)} - {fmt_time(hi)} | {notes.get(full_id, '')} |")
            if not rows:
                out.append("| (no estimate written) | | | |")
            out.append("")
        if not a.only:
            if sh(["cargo", "build", "--release", "-p", "atmo-sim"]).returncode != 0:
                sys.exit("benchmarks.py: cargo build --release -p atmo-sim failed")
            out += ["## Commands", "", "Wall time of each command on this machine, and its summary lines.", ""]
            for entry in spec.get("command", []):
                shown, wall, lines = run_command(entry, tmp)
                out += [f"### {entry['title']}", "", f"`{shown}`: {wall:.2f} s wall", "", "```"]
                out += lines
                out += ["```", ""]
    pathlib.Path(a.out).write_text("\n".join(out).rstrip() + "\n")
    print(f"wrote {a.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
