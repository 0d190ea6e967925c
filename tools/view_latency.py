#!/usr/bin/env python3
"""Benchmark, not a test: `tfmatch view`'s latency after a camera change, from a plain HTTP client.

Per camera change the four pictures are fetched in parallel, as the page fetches them (one
keep-alive connection per view), and timed from the first request to the last byte; each
picture's Server-Timing header gives the server's own breakdown (wait, render, readback, compose,
decorate, encode). Python's standard library only, so it runs on a lent GPU machine that has no
Node.js (tests/browser/camera_latency.mjs is the same measurement for this machine's Node).

    tools/view_latency.py PATH/TO/tfmatch [--size 512] [--changes 9] [--query Q] [--json FILE]
                          [-- VIEW ARGS...]

VIEW ARGS: what `tfmatch view` loads (default --demo, the 96^3 demo pair). Q: extra query
parameters of every picture request (default the page's "frame=fast&client=bench"; "" for
plain PNGs as downloads get them). Changes start at least 4/40 s apart: the server answers 429
beyond 40 pictures a second.

Prints the medians and "beyond the renders": (client time - the four renders' sum) / 4, per
picture; --json writes them with every sample.
"""
import argparse
import http.client
import json
import os
import re
import statistics
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor

VIEWS = ["reference", "field-ref-tf", "field-opt-tf", "residual"]
PICTURES_PER_SECOND = 40  # ViewServerOptions::device_requests_per_second


def server_timing(header):
    parts = {}
    for part in (header or "").split(","):
        m = re.match(r"\s*([a-z]+);dur=([0-9.]+)", part)
        if m:
            parts[m.group(1)] = float(m.group(2))
    return parts


def start_view(binary, view_args):
    """Starts `tfmatch view --port 0 ARGS`; returns (process, port, token) once it printed its URL."""
    proc = subprocess.Popen([binary, "view", "--port", "0", *view_args], stdout=subprocess.PIPE,
                            stderr=sys.stderr, text=True)
    found = {}

    def read():
        for line in proc.stdout:
            m = re.search(r"http://127\.0\.0\.1:(\d+)/\?token=([0-9a-f]+)", line)
            if m and not found:
                found["port"], found["token"] = int(m.group(1)), m.group(2)
        found.setdefault("ended", True)

    threading.Thread(target=read, daemon=True).start()
    deadline = time.monotonic() + 600
    while "port" not in found:
        if proc.poll() is not None or "ended" in found or time.monotonic() > deadline:
            proc.kill()
            sys.exit(f"view_latency: tfmatch view exited or printed no URL (status {proc.poll()})")
        time.sleep(0.05)
    return proc, found["port"], found["token"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("tfmatch")
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--changes", type=int, default=9)
    parser.add_argument("--query", default="frame=fast&client=bench")
    parser.add_argument("--pause", type=float, default=0.0,
                        help="seconds at least between camera changes (a user who stops dragging)")
    parser.add_argument("--json")
    argv = sys.argv[1:]
    dash = argv.index("--") if "--" in argv else len(argv)
    args = parser.parse_args(argv[:dash])
    view_args = argv[dash + 1:] or ["--demo"]
    if not os.access(args.tfmatch, os.X_OK):
        sys.exit(f"view_latency: {args.tfmatch} is not an executable (give the tfmatch program)")

    proc, port, token = start_view(args.tfmatch, view_args)
    connections = [http.client.HTTPConnection("127.0.0.1", port, timeout=300) for _ in VIEWS]

    def fetch(i, az, seq):
        query = f"view={VIEWS[i]}&az={az}&w={args.size}&h={args.size}&token={token}"
        if args.query:
            query += f"&{args.query}&seq={seq}"
        try:
            connections[i].request("GET", "/api/render?" + query)
            response = connections[i].getresponse()
        except (http.client.RemoteDisconnected, ConnectionResetError, BrokenPipeError):
            # The server closes a kept-alive connection idle for 2 s (a slow device keeps this
            # view's connection waiting that long for the other views): reconnect and ask again,
            # as a browser does.
            connections[i].close()
            connections[i].request("GET", "/api/render?" + query)
            response = connections[i].getresponse()
        body = response.read()
        if response.status != 200:
            raise RuntimeError(f"{VIEWS[i]}: HTTP {response.status} {body[:200]!r}")
        return server_timing(response.getheader("Server-Timing")), len(body)

    totals, renders, parts = [], [], {}
    try:
        with ThreadPoolExecutor(len(VIEWS)) as pool:
            last_start = 0.0
            for change in range(-2, args.changes):  # two warm-up changes: pipelines, first touch
                gap = max(len(VIEWS) / PICTURES_PER_SECOND, args.pause if change > -2 else 0.0)
                time.sleep(max(0.0, last_start + gap - time.monotonic()))
                last_start = time.monotonic()
                az, seq = 30 + 7 * (change + 2), change + 3
                t0 = time.perf_counter()
                results = list(pool.map(lambda i: fetch(i, az, seq), range(len(VIEWS))))
                total = (time.perf_counter() - t0) * 1e3
                if change < 0:
                    continue
                totals.append(total)
                renders.append(sum(t.get("render", 0.0) for t, _ in results))
                for t, size in results:
                    for key, value in {**t, "kB": size / 1024}.items():
                        parts.setdefault(key, []).append(value)
    finally:
        for c in connections:
            c.close()
        proc.terminate()
        proc.wait(timeout=30)

    beyond = [(t - r) / len(VIEWS) for t, r in zip(totals, renders)]
    summary = {
        "size": args.size,
        "changes": args.changes,
        "query": args.query,
        "view_args": view_args,
        "client_ms": totals,
        "client_ms_median": statistics.median(totals),
        "renders_ms_median": statistics.median(renders),
        "beyond_renders_per_picture_ms_median": statistics.median(beyond),
        "per_picture_median": {k: statistics.median(v) for k, v in parts.items()},
    }
    print(f"tfmatch view {' '.join(view_args)}: four {args.size}² pictures per camera change, "
          f"{args.changes} changes ({args.query or 'plain PNG'})")
    print(f"client: {', '.join(f'{t:.0f}' for t in totals)} ms; median {summary['client_ms_median']:.1f} ms")
    print(f"four renders (sum): median {summary['renders_ms_median']:.1f} ms; beyond the renders per picture: "
          f"median {summary['beyond_renders_per_picture_ms_median']:.1f} ms")
    print("per picture, median: " + ", ".join(f"{k} {v:.2f}" for k, v in summary["per_picture_median"].items()))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(summary, f, indent=1)


if __name__ == "__main__":
    main()
