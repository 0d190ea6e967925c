#!/usr/bin/env python3
"""Issues 28 and 29's GPU goals, each against what one tools/gpu-check.sh run measured.

A lent GPU machine gives a session about 15 minutes; reading its results should not take the
next session's hour. This reads the folder gpu-check.sh wrote (its JSON files and summary.txt)
and prints one Markdown table: every goal of the two issues' "Done when", what the run measured
for it, and a verdict — met, missed, not measured (and why: the step that did not run, failed or
ran another size), or no goal (measured, but the issue sets no figure for this device).

    tools/gpu_targets.py GPU_CHECK_DIR [--json FILE] [--any-size]

gpu-check.sh runs it after every step, into GPU_CHECK_DIR/targets.md. Goals that are a device's
own figure (the read bound, the assembly's 0.5 ms) apply to an H100 or H200, recognised by the
device name in the benchmarks' JSON; the goals relative to PyTorch or the CPU reference apply to
every device. Exit 0 whatever the verdicts; 1 for a file that is not JSON or not the shape its
command writes (named); 2 for usage errors. Standard library only.
"""
import argparse
import json
import os
import re
import sys

PAIR_VOXELS = 480 * 720 * 120      # the paper's Combustion size, issue 28's optimize goal
PAIR_DIMS = "480x720x120"
ASSEMBLY_TF_SIZES = (16, 64, 256, 1024)
MEMBERS = (10, 100, 1000)
CORRELATION_VOXELS = {10: 1_760_000, 100: 200_000, 1000: 20_000}  # bench-correlate's defaults
READ_BOUND_GOAL = {"H200": 3.0e12, "H100": 2.5e12}   # bytes/s: what PyTorch's sum reaches there
ASSEMBLY_MS_GOAL = {"H200": 0.5}
TORCH_TOLERANCE = 0.95             # "reaches PyTorch": within 5 %, one run's noise on a GPU
BENCH_VS_OPTIMIZE_TOLERANCE = 1.25  # "the same time inside bench and optimize"
STREAM_OFF_RATIO_GOAL = 1.5        # optimize of files not in the page cache / one read of them
CPU_RATIO_GOAL = 20.0              # kendall, mi-*: resident kernels >= 20x the CPU reference
CPU_RATIO_MEASURES = ("kendall", "mi-binned", "mi-kraskov", "mi-coefficient")
TORCH_MEASURES = ("pearson", "spearman")


class BadInput(Exception):
    pass


class Results:
    """The files of one gpu-check run: JSON by name (None where the step wrote none) and summary.txt."""

    def __init__(self, folder, any_size):
        self.folder = folder
        self.any_size = any_size  # judge runs of other sizes too (a test's small runs)
        self.steps = {}
        summary = os.path.join(folder, "summary.txt")
        if os.path.exists(summary):
            with open(summary) as f:
                for line in f:
                    m = re.match(r"(\S+)\s+(rc=(\d+)|skipped)", line)
                    if m:
                        self.steps[m.group(1)] = int(m.group(3)) if m.group(3) is not None else "skipped"

    def json(self, name):
        path = os.path.join(self.folder, name)
        if not os.path.exists(path):
            return None
        try:
            with open(path) as f:
                return json.load(f)
        except (OSError, ValueError) as e:
            raise BadInput(f"{path}: not a JSON file ({e})")

    def log(self, step):
        try:
            with open(os.path.join(self.folder, step + ".log"), errors="replace") as f:
                return f.read()
        except OSError:
            return ""

    def missing(self, step):
        """Why a step's results are absent, from summary.txt."""
        rc = self.steps.get(step)
        if rc is None:
            return f"step {step} did not run"
        if rc == "skipped":
            return f"step {step} skipped (deadline)"
        if rc == 124:
            return f"step {step} hit its time limit"
        return f"step {step} failed (rc={rc})" if rc else f"step {step} wrote no JSON"


def device_kind(name):
    for kind in READ_BOUND_GOAL:
        if kind in (name or ""):
            return kind
    return None


def tb(bytes_per_s):
    return f"{bytes_per_s / 1e12:.2f} TB/s" if bytes_per_s >= 1e11 else f"{bytes_per_s / 1e9:.1f} GB/s"


def rate(voxels_per_s):
    return f"{voxels_per_s:.3g}/s"


class Table:
    def __init__(self):
        self.rows = []

    def add(self, goal, target, measured, verdict, note=""):
        self.rows.append({"goal": goal, "target": target, "measured": measured, "verdict": verdict, "note": note})

    def judged(self, goal, target, measured, ok, note=""):
        self.add(goal, target, measured, "met" if ok else "missed", note)

    def absent(self, goal, target, why):
        self.add(goal, target, "—", "not measured", why)


def bench_goals(r, t, torch):
    goals = (("read bound", "≥ PyTorch's sum; 3.0 TB/s (H200), 2.5 TB/s (H100)"),
             ("assembly / read bound", f"≥ 0.50 at N = 16…1024, {PAIR_DIMS}"),
             ("upload", "≥ 40 GB/s (both fields, in place)"))
    bench = r.json("bench.json")
    runs = bench["runs"] if bench is not None else []
    run = max(runs, key=lambda x: x["voxels"]) if r.any_size and runs else \
        next((x for x in runs if x.get("dims") == PAIR_DIMS), None)
    if run is None:
        why = r.missing("bench") if bench is None else f"bench.json has no {PAIR_DIMS} run"
        for goal, target in goals:
            t.absent(goal, target, why)
        return None, None
    kind = device_kind(bench.get("device"))
    size_note = f"at {run['dims']}" if run.get("dims") != PAIR_DIMS else ""
    read = run["read_bound_voxels_per_s"] * 8
    torch_read = torch.get("read_bytes_per_s") if torch else None
    parts, ok = [], True
    if kind:
        parts.append(f"≥ {tb(READ_BOUND_GOAL[kind])} ({kind})")
        ok = read >= READ_BOUND_GOAL[kind]
    if torch_read:
        parts.append(f"≥ {TORCH_TOLERANCE:.2f} × PyTorch's sum, {tb(torch_read)}")
        ok = ok and read >= TORCH_TOLERANCE * torch_read
    if parts:
        t.judged("read bound", " and ".join(parts), tb(read), ok, size_note)
    else:
        t.add("read bound", "no figure for this device, no PyTorch run", tb(read), "no goal", size_note)

    by_n = {x["n"]: x for x in run["tf_sizes"]}
    have = [n for n in ASSEMBLY_TF_SIZES if n in by_n]
    if have:
        fractions = {n: by_n[n]["gpu_over_read_bound"] for n in have}
        text = ", ".join(f"N={n}: {f:.2f}" for n, f in fractions.items())
        lacking = [str(n) for n in ASSEMBLY_TF_SIZES if n not in by_n]
        note = "; ".join(x for x in (size_note, "no N = " + ", ".join(lacking) if lacking else "") if x)
        t.judged("assembly / read bound", goals[1][1], text, all(f >= 0.5 for f in fractions.values()) and not lacking,
                 note)
        if kind in ASSEMBLY_MS_GOAL:
            times = {n: by_n[n]["gpu_assemble_ms"] for n in have}
            t.judged("assembly time", f"≤ {ASSEMBLY_MS_GOAL[kind]} ms at N = 16…1024 ({kind})",
                     ", ".join(f"N={n}: {ms:.2f} ms" for n, ms in times.items()),
                     all(ms <= ASSEMBLY_MS_GOAL[kind] for ms in times.values()) and not lacking, note)
    else:
        t.absent("assembly / read bound", goals[1][1], f"bench.json has no N = 16…1024 at {run['dims']}")

    upload = run.get("upload_in_place_bytes_per_s")
    if upload is None:
        t.absent("upload", goals[2][1], "bench.json has no upload_in_place_bytes_per_s")
    else:
        staged = run.get("upload_staged_bytes_per_s")
        note = "; ".join(x for x in (size_note, f"staged {staged / 1e9:.1f} GB/s" if staged else "") if x)
        t.judged("upload", goals[2][1], f"{upload / 1e9:.1f} GB/s", upload >= 40e9, note)

    lanes = [x for x in run.get("lane_voxels", []) if x.get("same_sums")]
    if lanes:
        best = min(lanes, key=lambda x: x["assemble_ms"])
        t.add("lane length sweep", "the fastest becomes kVoxelLaneVoxels",
              f"{best['lane_voxels']} voxels: assembly {best['assemble_ms']:.3f} ms (N = 64)", "no goal",
              ", ".join(f"{x['lane_voxels']}: {x['assemble_ms']:.3f}" for x in lanes))
    return kind, by_n.get(64)


def optimize_assembly_goal(r, t, bench_n64, e2e):
    goal = "assembly in bench = in optimize"
    target = f"within {BENCH_VS_OPTIMIZE_TOLERANCE:.2f}× at N = 64, {PAIR_DIMS}"
    if e2e is None:
        t.absent(goal, target, r.missing("e2e"))
        return
    if bench_n64 is None:
        t.absent(goal, target, r.missing("bench") if r.json("bench.json") is None else
                 f"bench.json has no N = 64 run at {PAIR_DIMS}")
        return
    phases = e2e["optimize"].get("phases")
    inside = next((p.get("gpu_ms") for p in phases or [] if p.get("name") == "assemble"), None)
    if inside is None or not (e2e.get("default_sizes") or r.any_size):
        t.absent(goal, target, "e2e.json has no assemble phase at the default sizes")
        return
    alone = bench_n64["gpu_assemble_ms"]
    ratio = max(alone, inside) / min(alone, inside)
    t.judged(goal, target, f"bench {alone:.2f} ms, optimize {inside:.2f} ms", ratio <= BENCH_VS_OPTIMIZE_TOLERANCE)


def correlation_goals(r, t, torch):
    targets = {"pearson / read bound": "≥ 0.50 at M = 10, resident"}
    for measure in TORCH_MEASURES + CPU_RATIO_MEASURES:
        targets[measure] = ("≥ PyTorch on the same GPU" if measure in TORCH_MEASURES else
                            f"≥ {CPU_RATIO_GOAL:.0f}× the CPU reference") + ", resident, M = 10, 100, 1000"
    bc = r.json("bench-correlate.json")
    if bc is None:
        for goal, target in targets.items():
            t.absent(goal, target, r.missing("bench-correlate"))
        return
    rows = {(x["measure"], x["members"]): x for x in bc["results"]}

    def row_of(measure, m):
        """bench-correlate's row, or why there is none at the goal's size."""
        row = rows.get((measure, m))
        if row is None:
            return None, f"M = {m}: no row"
        if not r.any_size and row["voxels"] != CORRELATION_VOXELS[m]:
            return None, f"M = {m}: {row['voxels']} voxels, the goal's are {CORRELATION_VOXELS[m]}"
        return row, ""

    p10, why = row_of("pearson", 10)
    if p10 is None:
        t.absent("pearson / read bound", targets["pearson / read bound"], why)
    else:
        f = p10["resident_over_read_bound"]
        t.judged("pearson / read bound", targets["pearson / read bound"], f"{f:.2f}", f >= 0.5)
    peer = {(c["measure"], c["members"]): c for c in (torch or {}).get("correlation", [])}
    for measure in TORCH_MEASURES + CPU_RATIO_MEASURES:
        cells, ok, missing = [], True, []
        for m in MEMBERS:
            row, why = row_of(measure, m)
            if row is None:
                missing.append(why)
                continue
            ours = row["resident_voxels_per_s"]
            if measure in TORCH_MEASURES:
                theirs = peer.get((measure, m))
                if theirs is None or theirs["voxels"] != row["voxels"]:
                    missing.append(f"M = {m}: " + ("no PyTorch run" if torch is None else
                                                  "PyTorch has no row" if theirs is None else
                                                  f"PyTorch ran {theirs['voxels']} voxels, tfmatch {row['voxels']}"))
                    cells.append(f"M={m}: {rate(ours)}")
                    continue
                ok = ok and ours >= theirs["voxels_per_s"]
                cells.append(f"M={m}: {rate(ours)} vs {rate(theirs['voxels_per_s'])}")
            else:
                ratio = ours / row["cpu_voxels_per_s"]
                ok = ok and ratio >= CPU_RATIO_GOAL
                cells.append(f"M={m}: {ratio:.1f}× ({row['cpu_threads']} threads)")
        if missing:
            t.add(measure, targets[measure], "; ".join(cells) or "—", "not measured", "; ".join(missing))
        else:
            t.judged(measure, targets[measure], "; ".join(cells), ok)


def end_to_end_goals(r, t, e2e):
    goals = (("optimize", 350.0, f"{PAIR_DIMS}, N = 64"), ("correlate", 300.0, "10 × 1.76 M, pearson"))
    if e2e is None:
        for name, ms, what in goals:
            t.absent(f"{name} end to end", f"≤ {ms:.0f} ms, {what}, files cached", r.missing("e2e"))
        return
    floor = e2e.get("driver_floor", {}).get("total_ms")
    note = f"driver floor {floor:.0f} ms" if floor is not None else ""
    for name, ms, what in goals:
        run = e2e[name]
        target = f"≤ {ms:.0f} ms, {what}, files cached"
        if not (e2e.get("default_sizes") or r.any_size):
            t.absent(f"{name} end to end", target, "e2e.json ran other sizes")
        else:
            t.judged(f"{name} end to end", target, f"{run['median_ms']:.0f} ms (median)", run["median_ms"] <= ms, note)


def stream_off_goal(r, t):
    target = f"optimize / read ≤ {STREAM_OFF_RATIO_GOAL}, --stream off, 41.5 M voxels, page cache dropped"
    bs = r.json("bench-stream-off.json")
    if bs is None:
        t.absent("optimize from disk", target, r.missing("bench-stream-off"))
        return
    run = next((x for x in bs["runs"] if r.any_size or abs(x["voxels"] / PAIR_VOXELS - 1) < 0.05), None)
    if bs["stream"] != "off" or run is None:
        t.absent("optimize from disk", target, f"bench-stream-off.json ran --stream {bs['stream']} at "
                 + ", ".join(str(x["voxels"]) for x in bs["runs"]) + " voxels")
        return
    t.judged("optimize from disk", target, f"{run['optimize_over_read']:.2f} ({run['optimize_s']:.2f} s, "
             f"read {run['read_once_s']:.2f} s)", run["optimize_over_read"] <= STREAM_OFF_RATIO_GOAL)


def cuda_goals(r, t):
    goals = (("cuda-normal-equations", 240.0), ("cuda-cgls", 1000.0))
    sv = r.json("solvers-combustion.json")
    if sv is None:
        for name, ms in goals:
            t.absent(name, f"≤ {ms / 1000:g} s at {PAIR_DIMS}", r.missing("solvers-combustion"))
        return
    rows = {x["solver"]: x for x in sv["rows"]}
    for name, ms in goals:
        target = f"≤ {ms / 1000:g} s at {PAIR_DIMS}"
        if sv.get("voxels") != PAIR_VOXELS and not r.any_size:
            t.absent(name, target, f"solvers-combustion.json has {sv.get('voxels')} voxels")
        elif name not in rows:
            t.absent(name, target, "solvers-combustion.json has no row of it (CUDA plugin missing or failed?)")
        else:
            t.judged(name, target, f"{rows[name]['total_ms'] / 1000:.3f} s", rows[name]["total_ms"] <= ms)


def diffdvr_goal(r, t):
    bd = r.json("bench-diffdvr.json")
    if bd is None:
        t.absent("DiffDVR iteration / forward", "≤ 2.5×", r.missing("bench-diffdvr"))
        return
    rows = bd["iterations"]
    ratios = [(x["step_voxels"], x["iteration_over_forward_only"]) for x in rows]
    t.judged("DiffDVR iteration / forward", "≤ 2.5× at every step size",
             ", ".join(f"step {s}: {q:.2f}×" for s, q in ratios), bool(ratios) and all(q <= 2.5 for _, q in ratios))


def view_goals(r, t):
    for size, ms in ((512, 40.0), (1024, 120.0)):
        v = r.json(f"view-{size}.json")
        target = f"≤ {ms:.0f} ms for four {size}² pictures"
        if v is None:
            t.absent(f"view {size}²", target, r.missing(f"view-{size}"))
        else:
            median = v["client_ms_median"]
            beyond = v.get("beyond_renders_per_picture_ms_median")
            t.judged(f"view {size}²", target, f"{median:.1f} ms (median)", median <= ms,
                     f"{beyond:.1f} ms a picture beyond the renders" if beyond is not None else "")


def test_counts(log):
    """(tests run, tests skipped) from a ctest or GoogleTest log, or None where it says neither."""
    ctest = re.search(r"tests passed, \d+ tests failed out of (\d+)", log)
    if ctest:
        return int(ctest.group(1)), len(re.findall(r"\*\*\*Skipped", log))
    ran = re.search(r"\[=+\] (\d+) tests? from .* ran", log)
    if ran:
        skipped = re.search(r"\[  SKIPPED \] (\d+) tests?", log)
        return int(ran.group(1)), int(skipped.group(1)) if skipped else 0
    return None


def test_goals(r, t):
    # A skipped CUDA test ran nothing on the GPU; the suite skips a few tests anywhere (PyTorch,
    # a browser), so there only the exit code counts.
    for goal, steps, skips_count in (("test suite", ("ctest", "gtest"), False), ("self-test", ("selftest",), False),
                                     ("CUDA tests", ("cuda-tests",), True)):
        step = next((s for s in steps if s in r.steps), steps[0])
        rc = r.steps.get(step)
        if rc is None or rc == "skipped":
            t.absent(goal, "passes", r.missing(step))
            continue
        counts = test_counts(r.log(step)) if step != "selftest" else None
        text = f"rc={rc}" + (f"; {counts[0]} tests, {counts[1]} skipped" if counts else "")
        if rc == 0 and counts and counts[1] and (skips_count or counts[0] == counts[1]):
            t.add(goal, "passes", text, "not measured", f"{counts[1]} of {counts[0]} skipped (no such device?)")
        else:
            t.judged(goal, "passes", text, rc == 0)


def evaluate(folder, any_size=False):
    r = Results(folder, any_size)
    t = Table()
    torch = r.json("torch.json")
    e2e = r.json("e2e.json")
    def judge(name, goals):
        # A key or type a command's JSON does not have: the file is not what that command writes.
        try:
            return goals()
        except (KeyError, IndexError, TypeError, AttributeError, ZeroDivisionError) as e:
            raise BadInput(f"{os.path.join(folder, name)}: not the JSON its step writes "
                           f"({type(e).__name__}: {e})")

    kind, bench_n64 = judge("bench.json", lambda: bench_goals(r, t, torch))
    judge("e2e.json", lambda: optimize_assembly_goal(r, t, bench_n64, e2e))
    judge("bench-correlate.json", lambda: correlation_goals(r, t, torch))
    judge("e2e.json", lambda: end_to_end_goals(r, t, e2e))
    judge("bench-stream-off.json", lambda: stream_off_goal(r, t))
    judge("solvers-combustion.json", lambda: cuda_goals(r, t))
    judge("bench-diffdvr.json", lambda: diffdvr_goal(r, t))
    judge("view-*.json", lambda: view_goals(r, t))
    test_goals(r, t)
    devices = r.json("devices.json") or {}
    driver = next((d.get("driver") for d in devices.get("devices", []) if d.get("type") != "CPU"), None)
    return {"folder": folder, "device_kind": kind, "driver": driver,
            "torch": (torch or {}).get("torch"), "rows": t.rows}


def markdown(result):
    def cells(row):
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |"

    device = result["device_kind"] or "not an H100/H200"
    driver = result["driver"] or "not recorded (part check writes devices.json)"
    lines = [f"GPU goals of issues 28 and 29 in {result['folder']}: device {device}, driver {driver}, "
             f"PyTorch {result['torch'] or 'not run'}", "",
             cells(("goal", "target", "measured", "verdict", "note")), cells(("---",) * 5)]
    for x in result["rows"]:
        shown = f"**{x['verdict']}**" if x["verdict"] == "missed" else x["verdict"]
        lines.append(cells((x["goal"], x["target"], x["measured"], shown, x["note"])))
    counts = {}
    for x in result["rows"]:
        counts[x["verdict"]] = counts.get(x["verdict"], 0) + 1
    lines += ["", ", ".join(f"{v}: {counts[v]}" for v in ("met", "missed", "not measured", "no goal") if v in counts)]
    return "\n".join(lines) + "\n"


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("folder", help="what tools/gpu-check.sh wrote (its OUT_DIR)")
    p.add_argument("--json", help="also write the rows as JSON to this file")
    p.add_argument("--any-size", action="store_true",
                   help="judge results of any size against the goals (the largest bench run; "
                        "to test this table on small runs)")
    a = p.parse_args()
    if not os.path.isdir(a.folder):
        p.error(f"{a.folder}: no such folder")
    try:
        result = evaluate(a.folder, a.any_size)
    except BadInput as e:
        print(f"gpu_targets.py: {e}", file=sys.stderr)
        return 1
    sys.stdout.write(markdown(result))
    if a.json:
        with open(a.json + ".part", "w") as f:
            json.dump(result, f, indent=1)
        os.replace(a.json + ".part", a.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
